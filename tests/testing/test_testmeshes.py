"""The generated wing meshes (ffdcli.testing.gmsh_wings) and the robustness harness (benchmarks/bench_robustness)."""

from __future__ import annotations

import signal
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("gmsh")

from ffdcli.io.formats import read_mesh  # noqa: E402
from ffdcli.quality.metrics import cell_quality  # noqa: E402
from ffdcli.testing import gmsh_wings as tm  # noqa: E402

#: Small versions of three cases with variety (span z / -y / x, right / left, prisms, round tip, kink).
SMALL = {name: tm.smaller(tm.CASES[name], 1.8) for name in ("rect_z_bl_ff5", "left_swept_round", "transport_x_ff50")}


@pytest.fixture(scope="session")
def mesh_dir(tmp_path_factory):
    """Generated meshes, written once per session."""
    folder = tmp_path_factory.mktemp("testmeshes")
    for case in SMALL.values():
        tm.write_case(case, folder)
    return folder


def test_meshing_leaves_pythons_interrupt_handler_in_place(tmp_path):
    """gmsh's default (interruptible) sets SIGINT to SIG_DFL for good: a later Ctrl-C, or the
    interrupt tests of this suite, would then kill the interpreter instead of raising."""
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)    # whatever the suite inherited
    try:
        tm.write_case(tm.smaller(tm.CASES["rect_z_bl_ff5"], 2.5), tmp_path)   # meshes with gmsh
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, inherited)


def test_generated_meshes_are_valid_with_the_tip_inside(mesh_dir):
    for case in SMALL.values():
        mesh = read_mesh(tm.write_case(case, mesh_dir))
        assert set(mesh.markers) == {"wing", "symmetry", "farfield"}
        q = cell_quality(mesh.points, mesh.cells)
        assert q.min() > 0, case.name
        pf = case.planform
        s = pf.axes[2]
        wing = np.unique(np.concatenate([b.data.ravel() for b in mesh.markers["wing"]]))
        sym = np.unique(np.concatenate([b.data.ravel() for b in mesh.markers["symmetry"]]))
        # the root is in the symmetry plane; the far field reaches beyond the tip (tip inside the domain)
        assert np.all(mesh.points[sym, s] == pf.root_offset[s])
        tip = pf.span_sign * (mesh.points[wing, s] - pf.root_offset[s])
        reach = pf.span_sign * (mesh.points[:, s] - pf.root_offset[s])
        assert tip.min() >= -1e-12 and tip.max() >= pf.semi_span - 1e-9
        assert reach.max() > tip.max() + 0.9 * case.farfield * pf.root_chord
        if case.layers:
            types = [b.type for b in mesh.cells]
            assert types == ["tetra", "wedge"]
            assert [b.type for b in mesh.markers["symmetry"]] == ["triangle", "quad"]
            # thin layers: every wedge is much thinner than the wing's tetrahedra are wide
            w = mesh.cells[1].data
            h = np.linalg.norm(mesh.points[w[:, 3]] - mesh.points[w[:, 0]], axis=1)
            assert h.max() <= case.first_layer * case.growth ** case.layers * 10 * pf.root_chord


def test_the_wing_is_where_the_planform_says(mesh_dir):
    case = SMALL["left_swept_round"]
    mesh = read_mesh(tm.write_case(case, mesh_dir))
    pf = case.planform
    c, t, s = pf.axes
    wing = np.unique(np.concatenate([b.data.ravel() for b in mesh.markers["wing"]]))
    p = mesh.points[wing]
    assert pf.span_sign == -1 and p[:, s].min() == pytest.approx(-pf.semi_span - 0.06 * 0.5, rel=0.05)
    le_tip = pf.leading_edge(np.array([1.0]))[0]
    assert p[:, c].min() == pytest.approx(0.0, abs=1e-9)
    assert p[:, c].max() == pytest.approx(le_tip[c] + pf.chord(1.0), abs=0.02)


def test_case_keys_change_with_parameters():
    a = tm.CASES["rect_z"]
    assert a.key() == tm.CASES["rect_z"].key() and replace(a, farfield=7.0).key() != a.key()
    with pytest.raises(ValueError):
        tm.WingCase("bad", tip="pointy")


def test_robustness_harness_runs_in_quick_form(mesh_dir, tmp_path, monkeypatch):
    from benchmarks import bench_robustness as br

    for name, case in SMALL.items():
        monkeypatch.setitem(br.MESHES, f"gen:{name}", br.MeshSource(f"gen:{name}", "wing", bundled=str(
            tm.write_case(case, mesh_dir))))
    designs = ["twist_tip+10", "span1.1+sweep5", "shape_random"]
    rows = br.run_matrix([f"gen:{n}" for n in SMALL], designs, work=tmp_path)
    assert len(rows) == len(SMALL) * len(designs)
    for r in rows:
        assert r["status"] in ("ok", "REFUSED"), r
        assert r["q_before"] > 0 and r["q_after"] is not None
        assert r["max_disp"] > 0
        assert (r["status"] == "ok") == (r["failed"] == 0)
    table = br.matrix_table(rows)
    assert all(d in table for d in designs) and "deformations:" in table
    assert br.summary(rows)[0]["measured"] == sum(r["status"] == "REFUSED" for r in rows)


def test_compare_rows_names_every_difference_but_the_seconds(tmp_path):
    """``--compare``: two row files compared row by row (matched by mesh and design)."""
    import json

    from benchmarks import bench_robustness as br

    rng = np.random.default_rng(4)
    before = [{"mesh": m, "design": d, "status": "ok", "inverted": 0, "q_after": float(rng.uniform(0.01, 0.5)),
               "first_cell": [1.0, 1.0], "seconds": float(rng.uniform(1, 9))}
              for m in ("gen:a", "rect_wing") for d in ("twist_tip+10", "flap20", "sweep-5")]
    after = [dict(r, seconds=r["seconds"] + 1) for r in before]          # only the times differ
    assert br.compare_rows(before, after) == []
    after[1] = dict(after[1], status="REFUSED", inverted=3)
    after[4] = dict(after[4], first_cell=[0.999, 1.0])
    del after[5]
    after.append({"mesh": "rans:x", "design": "2d_flap10", "status": "ok"})
    lines = br.compare_rows(before, after)
    assert lines[0] == "only in the first: rect_wing / sweep-5"
    assert lines[1] == "only in the second: rans:x / 2d_flap10"
    assert lines[2] == "gen:a / flap20: inverted 0 -> 3; status 'ok' -> 'REFUSED'"
    assert lines[3].startswith("rect_wing / flap20: first_cell [1.0, 1.0] -> [0.999, 1.0]") and len(lines) == 4
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps(before))
    b.write_text(json.dumps(after))
    assert br.main(["--compare", str(a), str(a)]) == 0
    assert br.main(["--compare", str(a), str(b)]) == 1


#: Generated wings with variety on which the default volume settings must not invert a cell.
NO_INVERSION = {name: tm.smaller(tm.CASES[name], 1.5) for name in
                ("rect_z_bl_ff5", "transport_x_ff50", "blunt_te_x", "crm_metres")}


@pytest.mark.slow
def test_default_volume_settings_invert_no_cell_on_generated_wings(tmp_path_factory):
    """Span along z, x and y; prisms; a kink; a blunt trailing edge with a round tip; metres; far field at
    5, 10 and 50 chords: the planform changes of issue 13's table with the default volume settings."""
    from benchmarks import bench_robustness as br

    folder = tmp_path_factory.mktemp("noinv")
    designs = ["span1.1+sweep5", "sweep+10", "mix4_a", "twist_tip+10", "span1.15"]
    for name, case in NO_INVERSION.items():
        path = tm.write_case(case, folder / "meshes")
        for d in designs:
            row = br.run_one(path, "wing", d, work=folder)
            assert row["status"] in ("ok", "REFUSED"), row
            assert row["inverted"] == 0, (name, row)


#: Prism-layer wings with sharp trailing edges meeting the tip (the cells that inverted for almost every
#: design when the wall cells followed each face's own frame rotation), and one wing the defaults were
#: not chosen on (span along y, right, dihedral, 8 thin layers, NACA 2410 -> 0008, round tip).
SHARP_TIPS = {
    "left_swept_round": tm.smaller(tm.CASES["left_swept_round"], 1.8),
    "right_dihedral_zx_bl": tm.smaller(tm.CASES["right_dihedral_zx_bl"], 1.8),
}


@pytest.mark.slow
def test_default_settings_pass_the_gate_on_prism_wings_with_sharp_tips(tmp_path_factory):
    """Issue 13's target on prism-layer wings: every design passes the gate with the defaults (no
    inverted cell; cells squeezed by a halved tip chord are the design's own), while carrying only
    each face's frame rotation (``volume.carry: rotation``, IDWarp's form) inverts the wedges at the
    tip's sharp trailing edge under a plain tip twist."""
    from benchmarks import bench_robustness as br

    folder = tmp_path_factory.mktemp("sharp")
    designs = ["twist_tip+10", "dihedral+5", "chord_tip0.5", "chord_tip1.5", "shape_random", "mix4_c"]
    for name, case in SHARP_TIPS.items():
        path = tm.write_case(case, folder / "meshes")
        for d in designs:
            row = br.run_one(path, "wing", d, work=folder)
            assert row["status"] == "ok" and row["inverted"] == 0, (name, row)
    path = tm.write_case(SHARP_TIPS["left_swept_round"], folder / "meshes")
    row = br.run_one(path, "wing", "twist_tip+10", work=folder,
                     overrides=["volume.carry=rotation", "volume.alpha=4"])
    assert row["inverted"] > 0, row
