"""Every valid design either writes a mesh that reads back with the computed coordinates, or is refused
by the quality gate (exit 3): never a crash. Random designs, through the library and the command line.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REPO, SAMPLES, file_hash, run_ffd
from hostile import assert_hostile, design_with
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from wingcase import write_design, write_volume_wing

pytest_plugins = ["hostile"]        # the workspaces: fixtures ws, ws2


def test_absurd_twist_refused_by_quality_gate(ws):
    shutil.copyfile(SAMPLES / "rect_wing.su2", ws / "rect_wing.su2")
    data = yaml.safe_load((REPO / "configs" / "rect_twist_linear.yaml").read_text())
    data["mesh"] = "rect_wing.su2"
    data["changes"] = [{"twist": {"tip": 170}}]
    data["output"] = {"mesh": "out_absurd.su2", "lattice": "out_absurd_lattice.vtk"}
    (ws / "absurd.yaml").write_text(yaml.safe_dump(data))
    assert_hostile(ws, ["deform", "absurd.yaml"], 3, "quality", names=["absurd.yaml"])
    assert not (ws / "out_absurd.su2").exists()


N, M = 6, 8     # lattice points chordwise and spanwise of write_design's default box (6, 8, 2)


def small(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False).map(lambda x: round(x, 6))


CHANGE = st.one_of(
    st.builds(lambda t: {"twist": {"tip": t}}, small(-20, 20)),
    st.builds(lambda r, t: {"twist": {"root": r, "tip": t}}, small(-5, 5), small(-20, 20)),
    st.builds(lambda v: {"twist": v}, st.lists(small(-10, 10), min_size=M, max_size=M)),
    st.builds(lambda s: {"span": s}, small(0.6, 1.5)),
    st.builds(lambda d: {"sweep": d}, small(-30, 30)),
    st.builds(lambda d: {"dihedral": d}, small(-20, 20)),
    st.builds(lambda o: {"sweep": {"offsets": [0.0] + o}}, st.lists(small(-0.2, 0.2), min_size=M - 1,
                                                                    max_size=M - 1)),
    st.builds(lambda c: {"chord": {"tip": c}}, small(0.3, 2.0)),
    st.builds(lambda c: {"chord": c}, st.lists(small(0.5, 1.5), min_size=M, max_size=M)),
    st.builds(lambda u, lo: {"shape": {"upper": u, "lower": lo}},
              st.lists(small(-0.03, 0.03), min_size=N, max_size=N),
              st.lists(small(-0.03, 0.03), min_size=N, max_size=N)),
    st.builds(lambda a, s: {"shape": {"random": a, "seed": s}}, small(0, 0.05), st.integers(0, 2**31)),
)


DESIGN = st.lists(CHANGE, min_size=1, max_size=3)


@pytest.fixture(scope="module")
def wing(tmp_path_factory):
    d = tmp_path_factory.mktemp("props")
    mesh = write_volume_wing(d)
    return d, mesh, file_hash(mesh)


def _counts(mesh):
    return ({name: [(b.type, len(b)) for b in blocks] for name, blocks in mesh.markers.items()},
            [(b.type, len(b)) for b in mesh.cells])


def _check_written(path: Path, original, points_expected):
    from ffdcli.io.formats import read_mesh

    back = read_mesh(path)
    assert list(back.markers) == list(original.markers)
    assert _counts(back) == _counts(original)
    assert back.points.shape == original.points.shape
    assert np.all(np.isfinite(back.points))
    # SU2 ASCII keeps 17 significant digits here; 1e-12 of the wing size is far above that and far
    # below any displacement a change makes.
    assert np.allclose(back.points, points_expected, rtol=0, atol=1e-12 * np.ptp(original.points))


OUTCOMES: list[bool] = []       # quality verdicts of the drawn designs (both kinds must occur)


@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(changes=DESIGN)
def test_random_valid_designs_write_or_are_refused(wing, changes):
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run
    from ffdcli.app.write import write_outputs
    from ffdcli.design import load_design
    from ffdcli.errors import QualityError

    folder, mesh_path, mesh_hash = wing
    design_file = write_design(folder, mesh_path, changes, name="prop.yaml")
    out = folder / "out_prop.su2"
    out.unlink(missing_ok=True)
    design = load_design(design_file)
    run = load_run(design)
    try:
        result = deform(run)
    except QualityError:          # overflow-sized values: refused, nothing to write
        return
    q = result.quality
    assert q is not None
    OUTCOMES.append(q.ok)
    if not q.ok:                  # the CLI refuses it with exit 3 and writes nothing
        return
    written = write_outputs(run, result)
    assert Path(written["mesh"]) == out
    _check_written(out, run.prep.mesh, result.points)
    assert file_hash(mesh_path) == mesh_hash
    assert not list(folder.glob("*.part*"))


def test_random_designs_cover_both_outcomes():
    """The property above saw designs that were written and designs that the gate refused (runs after
    it, in file order; skipped when run alone)."""
    if not OUTCOMES:
        pytest.skip("run together with test_random_valid_designs_write_or_are_refused")
    assert any(OUTCOMES), OUTCOMES
    assert not all(OUTCOMES), OUTCOMES


@pytest.mark.slow
@pytest.mark.parametrize("changes,code", [
    ([{"twist": {"tip": 7.5}}, {"sweep": 12}, {"shape": {"random": 0.01, "seed": 3}}], 0),
    ([{"twist": {"tip": 90}}, {"chord": {"tip": 0.3}}], 3),
], ids=["valid", "gate"])
def test_cli_design_writes_or_is_refused(wing, changes, code):
    """The same property through the command line: exit 0 with a readable mesh, or exit 3 and nothing."""
    from ffdcli.io.formats import read_mesh

    folder, mesh_path, mesh_hash = wing
    name = f"cli_{len(changes)}_{abs(hash(json.dumps(changes))) % 10**6}.yaml"
    design_file = write_design(folder, mesh_path, changes, name=name)
    out = folder / f"out_{Path(name).stem}.su2"
    proc = run_ffd("deform", design_file.name, "--json", cwd=folder)
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.returncode == code, proc.stderr
    if proc.returncode == 3:
        assert not out.exists()
        assert "quality" in proc.stderr
    else:
        _check_written(out, read_mesh(mesh_path), read_mesh(out).points)
    assert file_hash(mesh_path) == mesh_hash



# ----------------------------------------------------------------------------------------------
# Issue 29: every path (recovery, --force, --json, MPI, DesignModel.write, plot) for every design form
# ----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def forms(tmp_path_factory):
    """The bundled multi-component forms (wing + tail + fin; a wing on a body) and a single wing, copied
    with their design files (no outputs: every test names its own)."""
    d = tmp_path_factory.mktemp("forms")
    for name, config in (("wing_tail_fin", "wing_tail_fin"), ("wing_body", "wing_body"),
                         ("rect_wing", "rect_twist_linear")):
        shutil.copyfile(SAMPLES / f"{name}.su2", d / f"{name}.su2")
        data = yaml.safe_load((REPO / "configs" / f"{config}.yaml").read_text())
        data["mesh"] = f"{name}.su2"
        data.pop("output", None)
        (d / f"{name}.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return d


#: The probe's case (recovered by the increments) and one the recovery cannot save (exit 3, --force writes).
RECOVERED = ("wing_tail_fin.yaml", "components.1.changes.0.dihedral=10")
REFUSED = ("wing_tail_fin.yaml", "components.1.changes.0={sweep: 15}")


@pytest.mark.slow
@pytest.mark.parametrize("how", ["deform", "json", "force", "plot"])
def test_a_multi_component_design_that_needs_the_recovery_runs_every_path(forms, how):
    """The probe: ``ffd deform configs/wing_tail_fin.yaml --set components.1.changes.0.dihedral=10``
    crashed in the recovery (it knew only the first component's surface), so did --force, --json and plot."""
    design, change = REFUSED if how == "force" else RECOVERED
    out = forms / f"rec_{how}.su2"
    if how == "plot":
        proc = run_ffd("plot", design, "--set", change, "-o", f"rec_{how}.png", cwd=forms)
        assert proc.returncode == 0, proc.stderr
        assert (forms / f"rec_{how}.png").exists()
        return
    args = ["deform", design, "--set", change, "-o", out.name, "--json"]
    if how == "force":
        proc = run_ffd(*args, cwd=forms)
        assert proc.returncode == 3 and "Traceback" not in proc.stderr, proc.stderr
        assert json.loads(proc.stdout)["exit_code"] == 3 and not out.exists()
        args.append("--force")
    proc = run_ffd(*args, cwd=forms)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert [a["attempt"] for a in summary["recovery"]][0] == "the design's volume settings"
    saved = [a["attempt"] for a in summary["recovery"] if a["ok"]]
    if how == "force":          # no attempt passed the gate: written anyway (the attempt that failed least)
        assert not saved and out.exists()
    else:
        assert saved and summary["recovered_with"] == saved[0] and out.exists()


@pytest.mark.slow
def test_the_api_writes_a_design_that_needs_the_recovery(forms):
    from ffdcli.api import DesignModel

    model = DesignModel.from_file(forms / RECOVERED[0], [RECOVERED[1]])
    written = model.write(forms / "rec_api.su2")
    assert Path(written["mesh"]).exists()


@pytest.mark.slow
def test_mpi_runs_a_design_that_needs_the_recovery_as_the_serial_run(forms):
    from test_mpi import MPIEXEC, _have_mpi4py, mpi_ffd

    if not (_have_mpi4py() and MPIEXEC):
        pytest.skip("the [mpi] extra (mpi4py + mpich) is not installed: pip install -e '.[mpi]'")
    serial = run_ffd("deform", RECOVERED[0], "--set", RECOVERED[1], "-o", "rec_serial.su2", "-q", cwd=forms)
    assert serial.returncode == 0, serial.stderr
    proc = mpi_ffd(2, "deform", RECOVERED[0], "--set", RECOVERED[1], "-o", "rec_mpi.su2", "--json", cwd=forms)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["recovered_with"] is not None
    assert file_hash(forms / "rec_mpi.su2") == file_hash(forms / "rec_serial.su2")


@settings(max_examples=6, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(form=st.sampled_from(["wing_tail_fin.yaml", "wing_body.yaml", "rect_wing.yaml"]),
       seed=st.integers(0, 2**16), steps=st.integers(1, 3))
def test_the_incremental_recovery_moves_every_component(forms, form, seed, steps):
    """The recovery's incremental warp on every form, for random moves of every component's lattice:
    finite, and every component's surface exactly where the FFD puts it."""
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design
    from ffdcli.volume.recovery import incremental_warp

    run = load_run(load_design(forms / form))
    rng = np.random.default_rng(seed)
    P1 = [c.freeze(c.P0 + rng.normal(scale=0.01, size=c.P0.shape) * np.ptp(c.P0.reshape(-1, 3), axis=0))
          for c in run.components]
    pts = incremental_warp(run.chain, P1, run.warp_settings, steps)
    mesh = run.prep.mesh
    assert pts.shape == mesh.points.shape and np.all(np.isfinite(pts))
    ids = run.surface_ids
    assert np.array_equal(pts[ids], mesh.points[ids] + run.surface_displacement(P1))


# ----------------------------------------------------------------------------------------------
# Issue 29: zero variables is a design (an empty gradient; a component without changes adds no columns)
# ----------------------------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("with_changes", [(False, False, False), (True, False, False), (False, True, False),
                                          (False, False, True), (True, True, False), (True, False, True)],
                         ids=lambda w: "".join("x" if c else "-" for c in w))
def test_components_without_changes_add_no_columns(forms, with_changes):
    """The probe: ``cannot reshape array of size 0`` in grad, jacobian, constraints --jacobian and the
    API whenever a component (or the whole design) had no change."""
    from ffdcli.api import DesignModel

    data = yaml.safe_load((forms / "wing_tail_fin.yaml").read_text())
    for comp, keep in zip(data["components"], with_changes, strict=True):
        if not keep:
            comp["changes"] = []
        comp["constraints"] = [{"volume": {"lower": 0.5}}]
    name = "zero_" + "".join("x" if c else "-" for c in with_changes) + ".yaml"
    (forms / name).write_text(yaml.safe_dump(data, sort_keys=False))
    model = DesignModel.from_file(forms / name)
    n = model.n_vars
    assert n == len(model.names) == sum(with_changes)       # one variable per change in this file
    S = len(model.surface_ids)
    J = model.lattice_jacobian()
    assert J.shape[1] == n and model.jacobian_factors()[1].shape == J.shape
    assert model.surface_vjp(np.ones((S, 3))).shape == (n,)
    assert model.surface_jvp(np.zeros(n)).shape == (S, 3)
    assert model.constraint_jacobian().shape == (3, n)
    model.add_points("probe", model.surface_points()[:5])
    assert model.points_vjp("probe", np.ones((5, 3))).shape == (n,)
    assert model.points_jvp("probe", np.zeros(n)).shape == (5, 3)


@pytest.mark.slow
def test_the_unedited_starter_file_differentiates(tmp_path):
    """``ffd init``'s file changes nothing: grad gives {}, jacobian and constraints --jacobian 0 columns."""
    shutil.copyfile(SAMPLES / "naca0012_2d.su2", tmp_path / "naca0012_2d.su2")
    shutil.copyfile(SAMPLES / "naca0012_2d_cd_sens.csv", tmp_path / "sens.csv")
    assert run_ffd("init", "naca0012_2d.su2", "-o", "start.yaml", cwd=tmp_path).returncode == 0
    proc = run_ffd("grad", "start.yaml", "--sens", "sens.csv", "--json", "-o", "g.json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["gradient"] == {} and json.loads((tmp_path / "g.json").read_text()) == {}
    assert run_ffd("jacobian", "start.yaml", "-o", "j.npz", "--dense", cwd=tmp_path).returncode == 0
    with np.load(tmp_path / "j.npz") as z:
        assert z["D"].shape[1] == 0 and z["J"].shape[1] == 0 and len(z["names"]) == 0
    proc = run_ffd("constraints", "start.yaml", "--jacobian", "c.npz", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr


# ----------------------------------------------------------------------------------------------
# Issue 29: OpenMDAO names unique and reversible for every design the file format allows
# ----------------------------------------------------------------------------------------------

KINDS = ["twist", "span", "sweep", "dihedral", "chord", "shape"]
SUFFIX = {"twist": [".tip", "[0]", "[3]", ".root"], "span": [""], "sweep": ["", ".offsets[2]"],
          "dihedral": ["", ".offsets[1]"], "chord": [".tip", "[1]"], "shape": [".upper[2]", ".lower[0]", "[5]"]}
#: Names a probe would try: like a change (c1), like an input (c0_twist), like a constraint (k0), with '-'.
NAME = st.one_of(st.sampled_from(["c1", "c0", "c0_twist", "k0", "k0_volume", "wing", "wing-1", "wing_1", "_", "c1_c0"]),
                 st.from_regex(r"[A-Za-z_][A-Za-z0-9_-]{0,6}", fullmatch=True))


@settings(max_examples=200, deadline=None, derandomize=True)
@given(comps=st.lists(st.tuples(NAME, st.lists(st.sampled_from(KINDS), min_size=0, max_size=5)), min_size=1,
                      max_size=4, unique_by=lambda c: c[0]), single=st.booleans())
def test_openmdao_names_are_unique_and_reversible(comps, single):
    pytest.importorskip("openmdao")                 # ffdcli.openmdao imports it (the [openmdao] extra)
    from ffdcli.openmdao import constraint_output, input_name, input_parts

    comps = comps[:1] if single else comps
    inputs = {}
    for comp, kinds in comps:
        prefix = "" if single else f"{comp}."
        for i, kind in enumerate(kinds):
            for suffix in SUFFIX[kind]:
                name = input_name(f"{prefix}c{i}.{kind}{suffix}")
                inputs.setdefault(name, set()).add((None if single else comp, i, kind))
                assert input_parts(name) == (None if single else comp, i, kind)
    assert all(len(owners) == 1 for owners in inputs.values()), inputs
    outs = [constraint_output("" if single else comp, k, kind) for comp, _ in comps for k, kind in
            enumerate(["volume", "thickness", "volume"])]
    assert len(set(outs)) == len(outs)
    assert not set(outs) & set(inputs)


@pytest.mark.slow
def test_openmdao_component_of_two_components_with_volume_constraints(forms):
    """The probe: two components each with a volume constraint failed in setup ("'k0_volume' already
    exists"), and a component named c1 merged two variables into one input ``c1_c``."""
    pytest.importorskip("openmdao")
    import openmdao.api as om

    from ffdcli.openmdao import FFDComponent, input_parts

    data = yaml.safe_load((forms / "wing_tail_fin.yaml").read_text())
    data["components"][0]["name"] = "c1"
    data["components"][0]["changes"] = [{"twist": {"tip": -3}}, {"chord": {"tip": 0.9}}]
    for comp in data["components"][:2]:
        comp["constraints"] = [{"volume": {"lower": 0.5}}]
    (forms / "om.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    prob = om.Problem()
    comp = FFDComponent(design=str(forms / "om.yaml"))
    prob.model.add_subsystem("ffd", comp, promotes=["*"])
    prob.setup()
    prob.run_model()
    assert comp.input_names == ["c1_c0_twist", "c1_c1_chord", "htail_c0_dihedral", "vfin_c0_sweep"]
    assert [input_parts(n) for n in comp.input_names][1] == ("c1", 1, "chord")
    assert prob["c1_k0_volume"].shape == (1,) and prob["htail_k0_volume"].shape == (1,)


@pytest.mark.parametrize("change", [{"span": 1e300}, {"chord": {"tip": 1e300}}])
def test_constraints_that_overflow_are_an_error_never_nan(ws, change):
    """No command reports or writes a non-finite number as a result: constraint values that overflow
    (far too large design values) are exit 2 naming the item, no ``null``/NaN value, no Jacobian file."""
    name = design_with(ws, f"overflow_{next(iter(change))}.yaml", [change],
                       constraints=[{"volume": {"lower": 1}}, {"thickness": {"chord": [0.5], "span": [0.5]}}])
    line = assert_hostile(ws, ["constraints", name, "--json", "--jacobian", "overflow.npz"], 2, "not a finite number",
                          names=[name])
    assert "constraint k" in line
