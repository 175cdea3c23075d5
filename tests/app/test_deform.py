"""`ffd deform` end to end: the SPEC's oracles on wings built in the tests, and the CLI contract."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import yaml
from conftest import REPO, run_ffd, shared_file
from wingcase import write_design, write_surface_wing

from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.app.write import write_outputs
from ffdcli.design import load_design
from ffdcli.io.formats import read_mesh
from ffdcli.testing.wings import Planform

# Global changes (span, sweep, dihedral, uniform twist) are affine maps of the whole lattice, so by
# affine invariance of B-splines every surface point moves by the same map: exact to rounding of
# O(1) coordinates through a few matrix products, 1e-12. Where a change acts per section, the oracle
# is exact only at the root and tip planes (they are lattice ends): also 1e-12 there.
EXACT = 1e-12


def run_design(tmp_path, changes, *, mesh=None, **kw):
    mesh = mesh or write_surface_wing(tmp_path, **kw.pop("planform", {}))
    design = load_design(write_design(tmp_path, mesh, changes, **kw))
    run = load_run(design)
    return run, deform(run)


def points_of(run, res):
    return run.prep.surface.points, res.points[run.prep.surface.ids]


def rotate_about(X, p, axis_c, axis_t, theta_deg):
    """Rotate points about the span-parallel axis through p: positive raises the leading edge."""
    th = np.radians(theta_deg)
    Y = X.copy()
    dc, dt = X[:, axis_c] - p[axis_c], X[:, axis_t] - p[axis_t]
    # nose up: the leading edge (dc < 0 from the trailing edge) moves to +thickness
    Y[:, axis_c] = p[axis_c] + np.cos(th) * dc + np.sin(th) * dt
    Y[:, axis_t] = p[axis_t] - np.sin(th) * dc + np.cos(th) * dt
    return Y


def test_no_change_is_bit_for_bit(tmp_path):
    mesh = write_surface_wing(tmp_path, le_sweep_deg=20)
    run, res = run_design(tmp_path, [{"twist": {"tip": 0}}], mesh=mesh)
    np.testing.assert_array_equal(res.points, run.prep.mesh.points)
    out = write_outputs(run, res)
    assert open(out["mesh"], "rb").read() == mesh.read_bytes()


def test_span_scales_semispan_exactly(tmp_path):
    run, res = run_design(tmp_path, [{"span": 1.1}], planform=dict(le_sweep_deg=30, taper=0.4))
    X0, X1 = points_of(run, res)
    z0, z1 = X0[:, 2], X1[:, 2]
    assert z1.max() == pytest.approx(1.1 * z0.max(), abs=EXACT)
    np.testing.assert_allclose(z1, 1.1 * z0, atol=EXACT)
    np.testing.assert_allclose(X1[:, :2], X0[:, :2], atol=EXACT)     # chords unchanged
    root = z0 == 0
    np.testing.assert_array_equal(X1[root], X0[root])


def le_angle(run, X, along, across):
    """Angle of the line through the surface's leading-edge points at root and tip."""
    le = run.box.frame.le_points(run.box.control_points) if X is None else X
    d = le[1] - le[0]
    return np.arctan2(d[along], d[across])


@pytest.mark.parametrize("kind,delta", [("sweep", 10.0), ("sweep", -5.0), ("dihedral", 5.0), ("dihedral", -5.0)])
def test_sweep_and_dihedral_change_the_le_angle_exactly(tmp_path, kind, delta):
    pf = dict(le_sweep_deg=25, dihedral_deg=3, taper=0.5)
    run, res = run_design(tmp_path, [{kind: delta}], planform=pf)
    X0, X1 = points_of(run, res)
    p = Planform(**pf)
    # Surface leading-edge points at the root and tip planes (they lie on the planform's LE line).
    z = X0[:, 2]
    ids = [np.flatnonzero(z == z.min()), np.flatnonzero(z == z.max())]
    le0 = np.array([X0[i[np.argmin(X0[i, 0])]] for i in ids])
    le1 = np.array([X1[i[np.argmin(X0[i, 0])]] for i in ids])
    col = 0 if kind == "sweep" else 1
    base = p.le_sweep_deg if kind == "sweep" else p.dihedral_deg
    a0 = np.degrees(np.arctan2(le0[1, col] - le0[0, col], le0[1, 2] - le0[0, 2]))
    a1 = np.degrees(np.arctan2(le1[1, col] - le1[0, col], le1[1, 2] - le1[0, 2]))
    assert a0 == pytest.approx(base, abs=1e-9)
    assert a1 == pytest.approx(base + delta, abs=np.degrees(1e-9))
    # A shear: only that axis moves, by an amount linear in span distance.
    other = 1 - col
    np.testing.assert_allclose(X1[:, [other, 2]], X0[:, [other, 2]], atol=EXACT)
    shift = (np.tan(np.radians(base + delta)) - np.tan(np.radians(base))) * X0[:, 2]
    np.testing.assert_allclose(X1[:, col] - X0[:, col], shift, atol=1e-11)


def test_twist_list_rotates_tip_about_its_trailing_edge_root_fixed(tmp_path):
    twist = [0, 10, 10, 12, 15, 15, 16, -22]
    run, res = run_design(tmp_path, [{"twist": twist}], planform=dict(taper=0.6))
    X0, X1 = points_of(run, res)
    z = X0[:, 2]
    root, tip = z == z.min(), z == z.max()
    np.testing.assert_array_equal(X1[root], X0[root])
    te_tip = run.box.te_points[-1]
    np.testing.assert_allclose(X1[tip], rotate_about(X0[tip], te_tip, 0, 1, -22.0), atol=EXACT)
    # positive twist raises the leading edge: at mid-span (twist > 0) the LE point moves up
    mid = np.abs(z - z.max() / 2) < 1e-9
    if mid.any():
        i = np.flatnonzero(mid)[np.argmin(X0[mid, 0])]
        assert X1[i, 1] > X0[i, 1]


def test_chord_scales_tip_about_te_keeping_thickness_to_chord(tmp_path):
    run, res = run_design(tmp_path, [{"chord": {"tip": 0.6}}], planform=dict(le_sweep_deg=15))
    X0, X1 = points_of(run, res)
    z = X0[:, 2]
    tip = z == z.max()
    te = run.box.te_points[-1]
    expect = X0[tip].copy()
    expect[:, :2] = te[:2] + 0.6 * (X0[tip, :2] - te[:2])
    np.testing.assert_allclose(X1[tip], expect, atol=EXACT)
    c0 = np.ptp(X0[tip, 0])
    c1, t0, t1 = np.ptp(X1[tip, 0]), np.ptp(X0[tip, 1]), np.ptp(X1[tip, 1])
    assert c1 == pytest.approx(0.6 * c0, abs=EXACT)
    assert t1 / c1 == pytest.approx(t0 / c0, abs=1e-12)
    root = z == z.min()
    np.testing.assert_array_equal(X1[root], X0[root])


def test_shape_moves_only_along_thickness(tmp_path):
    up = [0, 0.01, 0.015, 0.01, 0.005, 0]
    lo = [0, -0.005, -0.01, -0.005, 0, 0]
    run, res = run_design(tmp_path, [{"shape": {"upper": up, "lower": lo, "sections": "all"}}])
    X0, X1 = points_of(run, res)
    np.testing.assert_array_equal(X1[:, [0, 2]], X0[:, [0, 2]])
    assert np.abs(X1[:, 1] - X0[:, 1]).max() > 1e-3


def test_composition_order_matters_and_matches_direct(tmp_path):
    """Tip twist then sweep differs from sweep then tip twist: the twist moves the tip leading edge,
    so the sweep angle the shear starts from differs. Both orders match the direct computation at
    the root and tip planes (lattice ends, where per-section maps act exactly)."""
    mesh = write_surface_wing(tmp_path)
    tw = {"twist": {"tip": 20}}
    sw = {"sweep": 10}
    runA, resA = run_design(tmp_path, [tw, sw], mesh=mesh)
    runB, resB = run_design(tmp_path, [sw, tw], mesh=mesh)
    X0, XA = points_of(runA, resA)
    _, XB = points_of(runB, resB)
    z = X0[:, 2]
    root, tip = z == z.min(), z == z.max()
    np.testing.assert_array_equal(XA[root], X0[root])
    np.testing.assert_array_equal(XB[root], X0[root])
    te = runA.box.te_points[-1]                      # (1, 0, 3)
    le_root = np.array([0.0, 0.0, 0.0])
    le_tip = np.array([0.0, 0.0, 3.0])
    # A: rotate the tip about its trailing edge, then shear along chord.
    A = rotate_about(X0[tip], te, 0, 1, 20.0)
    le_tip_a = rotate_about(le_tip[None], te, 0, 1, 20.0)[0]
    lam = np.arctan2(le_tip_a[0] - le_root[0], le_tip_a[2] - le_root[2])
    A[:, 0] += (np.tan(lam + np.radians(10)) - np.tan(lam)) * 3.0
    np.testing.assert_allclose(XA[tip], A, atol=EXACT)
    # B: shear (from sweep 0), then rotate the tip about its moved trailing edge.
    shift = np.tan(np.radians(10)) * 3.0
    B = X0[tip].copy()
    B[:, 0] += shift
    B = rotate_about(B, te + np.array([shift, 0, 0]), 0, 1, 20.0)
    np.testing.assert_allclose(XB[tip], B, atol=EXACT)
    assert np.abs(XA[tip] - XB[tip]).max() > 1e-3   # 2.1e-3 chord here


def test_written_mesh_keeps_markers_and_lattice_vtk(tmp_path):
    mesh = write_surface_wing(tmp_path)
    run, res = run_design(tmp_path, [{"dihedral": 5}], mesh=mesh)
    out = write_outputs(run, res)
    back = read_mesh(out["mesh"])
    assert list(back.markers) == list(run.prep.mesh.markers)
    np.testing.assert_array_equal(back.points, res.points)
    from ffdcli.io.formats.lattice_vtk import read_lattice_vtk

    lat = read_lattice_vtk(out["lattice"])
    np.testing.assert_allclose(lat["points"], res.lattice, atol=1e-15)
    np.testing.assert_allclose(lat["displacement"], res.lattice - run.P0, atol=1e-15)


def test_cli_deform_json_and_set(tmp_path):
    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"twist": {"tip": 5}}])
    before = mesh.read_bytes()
    proc = run_ffd("deform", str(design), "--json", "--set", "changes.0.twist.tip=12",
                   "-o", str(tmp_path / "t12.su2"))
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    for key in ("output", "max_displacement", "changes", "seconds"):
        assert key in s
    assert s["changes"] == ["twist"] and s["output"].endswith("t12.su2")
    assert mesh.read_bytes() == before
    # the --set value is the one used: tip trailing edge fixed, tip rotated by 12 degrees
    X1 = read_mesh(tmp_path / "t12.su2").points
    X0 = read_mesh(mesh).points
    tip = X0[:, 2] == X0[:, 2].max()
    i = np.flatnonzero(tip)[np.argmin(X0[tip, 0])]       # tip leading edge
    te = np.flatnonzero(tip)[np.argmax(X0[tip, 0])]
    ang = np.degrees(np.arctan2(X1[i, 1] - X1[te, 1], X1[te, 0] - X1[i, 0]))
    assert ang == pytest.approx(12.0, abs=1e-9)


def test_a_refused_device_near_the_root_is_told_to_leave_its_blend_room(tmp_path):
    """A flap 0.02 from the root fades over 0.02 of the span, not its blend's 0.2: at 30 degrees the
    gate refuses it (exit 3, nothing written) and the message says which device and what to change;
    done so (the flap from 0.2), the gate passes it."""
    mesh = tmp_path / "rect_wing.su2"
    shutil.copyfile(REPO / "samples" / "rect_wing.su2", mesh)
    design = write_design(tmp_path, mesh, [{"flap": {"span": [0.02, 0.4], "hinge": 0.72, "angle": 30}}],
                          sections="xy")
    proc = run_ffd("deform", design)
    assert proc.returncode == 3, proc.stderr
    assert ("c0's flap fades over only 0.02 of the span at its inner end (the root is nearer than its blend "
            "0.2): end it at least 0.2 from the root") in proc.stderr
    assert not any(tmp_path.glob("out_*"))
    ok = run_ffd("deform", design, "--set", "changes.0.flap.span=[0.2, 0.4]")
    assert ok.returncode == 0, ok.stderr


@pytest.mark.parametrize("changes", [[{"twist": 2}], [{"twist": -3.5}], [{"shape": {"random": 0.004, "seed": 3}}]])
def test_volume_method_none_hands_the_volume_over_without_judging_it(tmp_path, changes):
    """Issue 43, item 18: ``volume.method: none`` with ``--surface-file`` (docs/su2.md's path for SU2_DEF's
    own volume motion): the unmoved volume's cells beside the moved surface are not the design's, so the
    gate does not judge them (was: exit 3 blaming "108 cells inverted by the design" on a RANS mesh for
    a 2 degree twist, and no surface file). The surface file is written, a warning says the volume was
    not moved; the same design with the volume moved by ffd passes the gate."""
    mesh = shared_file("su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2")
    data = {"mesh": str(mesh), "surface": "AIRFOIL", "volume": {"method": "none"}, "changes": changes,
            "output": {"mesh": "out.su2"}}
    design = tmp_path / "d.yaml"
    design.write_text(yaml.safe_dump(data))
    proc = run_ffd("deform", design, "--surface-file", "surf.dat", "--cache-dir", tmp_path, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "volume mesh was not moved" in proc.stderr and "SU2_DEF" in proc.stderr
    rows = [ln.split() for ln in (tmp_path / "surf.dat").read_text().splitlines() if ln.strip()]
    assert len(rows) == 192
    out = read_mesh(tmp_path / "out.su2")
    moved = np.array([[float(x) for x in r[1:3]] for r in rows])
    ids = np.array([int(r[0]) for r in rows])
    assert np.abs(out.points[ids, :2] - moved).max() < 1e-9
    inp = read_mesh(mesh)
    assert np.abs(out.points[ids] - inp.points[ids]).max() > 1e-4          # the surface moved
    volume = np.setdiff1d(np.arange(len(inp.points)), ids)
    np.testing.assert_array_equal(out.points[volume], inp.points[volume])  # the volume did not
