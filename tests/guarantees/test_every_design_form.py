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
from hostile import (
    assert_hostile,
)
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

