"""Issue 15: ffd vars, ffd constraints (--json, --jacobian), bounds: and constraints: in the design file."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from conftest import assert_clean_failure, run_ffd
from wingcase import write_design, write_surface_wing

from ffdcli.api import DesignModel
from ffdcli.design import design_schema, load_design
from ffdcli.errors import InputError

CHANGES = [{"twist": {"tip": 3}}, {"span": 1.1}, {"chord": {"tip": 0.9}},
           {"shape": {"upper": [0, 0.01, 0.01, 0.01, 0, 0], "lower": [0, -0.01, 0, 0, 0, 0]}}]
CONSTRAINTS = [{"thickness": {"chord": [0.2, 0.5, 0.8], "span": [0.1, 0.9], "lower": 1.0}},
               {"thickness_to_chord": {"chord": [0.3], "span": [0.0, 1.0], "lower": 1.0}},
               {"volume": {"lower": 1.0}}, {"le_te": {}}, {"fold_free": {"lower": 0.2}}]


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cli")
    mesh = write_surface_wing(tmp, sections="xz", taper=0.6)
    design = write_design(tmp, mesh, CHANGES, extra={"constraints": CONSTRAINTS,
                                                     "bounds": {"c0.twist": [-10, 10], "c1.span": {"upper": 1.5}}})
    return tmp, design


def test_schema_has_constraints_and_bounds():
    props = design_schema()["properties"]
    assert "constraints" in props and "bounds" in props


def test_ffd_vars_json(case):
    _, design = case
    proc = run_ffd("vars", str(design), "--json")
    assert proc.returncode == 0, proc.stderr
    rows = {r["name"]: r for r in json.loads(proc.stdout)["variables"]}
    assert rows["c0.twist.tip"] == {"name": "c0.twist.tip", "value": 3.0, "unit": "deg", "lower": -10.0, "upper": 10.0}
    assert rows["c1.span"] == {"name": "c1.span", "value": 1.1, "unit": "factor", "lower": 0.0, "upper": 1.5}
    assert rows["c3.shape.upper[1]"]["lower"] is None and rows["c3.shape.upper[1]"]["unit"] == "length"
    text = run_ffd("vars", str(design))
    assert text.returncode == 0 and "c2.chord.tip" in text.stdout and "factor" in text.stdout


def test_ffd_constraints_json_and_jacobian(case):
    tmp, design = case
    npz = tmp / "jac.npz"
    proc = run_ffd("constraints", str(design), "--json", "--jacobian", str(npz))
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    rows = out["constraints"]
    assert [r["name"] for r in rows][:2] == ["k0.thickness[0]", "k0.thickness[1]"]
    vol = next(r for r in rows if r["name"] == "k2.volume")
    model = DesignModel.from_file(design)
    expected = model.constraint_values()[model.constraint_names.index("k2.volume")]
    assert vol["value"] == pytest.approx(expected, rel=1e-14)
    assert vol["lower"] == 1.0 and vol["upper"] is None and isinstance(vol["satisfied"], bool)
    assert {"name", "value", "unit", "lower", "upper"} <= set(out["variables"][0])
    data = np.load(npz)
    assert list(data["names"]) == model.constraint_names and list(data["variables"]) == model.names
    assert data["jacobian"].shape == (len(rows), model.n_vars)
    np.testing.assert_allclose(data["jacobian"], model.constraint_jacobian(), atol=1e-14)
    np.testing.assert_allclose(data["values"], model.constraint_values(), atol=1e-14)
    assert data["lower"].shape == data["upper"].shape == (len(rows),)
    # --set moves the values; the chord at the tip thins the tip grid point below 1
    proc = run_ffd("constraints", str(design), "--set", "changes.2.chord.tip=0.5", "--json")
    rows = {r["name"]: r for r in json.loads(proc.stdout)["constraints"]}
    assert not rows["k0.thickness[3]"]["satisfied"] and rows["k0.thickness[3]"]["value"] < 1
    text = run_ffd("constraints", str(design))
    assert text.returncode == 0 and "k4.fold_free" in text.stdout and "satisfied" in text.stdout


def test_deform_json_has_the_constraints(case):
    tmp, design = case
    proc = run_ffd("deform", str(design), "--json", "-o", str(tmp / "d.su2"))
    assert proc.returncode == 0, proc.stderr
    rows = json.loads(proc.stdout)["constraints"]
    assert any(r["name"] == "k2.volume" for r in rows)


def _with(tmp, extra, name="bad.yaml"):
    mesh = tmp / "wing.su2"
    return write_design(tmp, mesh, CHANGES, name=name, extra=extra)


@pytest.mark.parametrize("extra, words", [
    ({"constraints": [{"wobble": {}}]}, ["constraints[0]", "wobble"]),
    ({"constraints": [{"volume": {"lowr": 1}}]}, ["constraints[0].volume", "lowr"]),
    ({"constraints": [{"thickness": {"chord": [0.5], "span": [1.5]}}]}, ["constraints[0].thickness.span[0]"]),
    ({"constraints": [{"thickness": {"chord": [0.999999999], "span": [0.5]}}]}, ["constraints[0].thickness", "misses"]),
    ({"constraints": [{"thickness": {"chord": [1.0], "span": [0.5]}}]}, ["constraints[0].thickness.chord[0]",
                                                                        "less than 1"]),
    ({"bounds": {"c9.twist": [0, 1]}}, ["bounds.c9.twist", "no design variable"]),
    ({"bounds": {"c1.span": [1.2, 1.5]}}, ["bounds.c1.span", "outside its bounds"]),
    ({"bounds": {"c1.span": [1, 2, 3]}}, ["bounds.c1.span"]),
])
def test_bad_input_exit_2_naming_key_and_line(case, extra, words):
    tmp, _ = case
    design = _with(tmp, extra)
    proc = run_ffd("constraints", str(design))
    assert_clean_failure(proc, 2, "bad.yaml", *words)
    text = design.read_text().splitlines()
    key = words[0].split(".")[0].split("[")[0]
    line = next(i + 1 for i, t in enumerate(text) if t.startswith(key + ":"))
    assert f":{line}" in proc.stderr or f"line {line}" in proc.stderr or any(
        f":{n}" in proc.stderr for n in range(line, len(text) + 1)), proc.stderr


def test_2d_span_has_no_meaning(tmp_path):
    from ffdcli.io.formats import write_mesh
    from ffdcli.testing.wings import airfoil_ogrid_mesh

    write_mesh(airfoil_ogrid_mesh("0012", n_around=65, n_radial=9), tmp_path / "foil.su2")
    design = tmp_path / "foil.yaml"
    design.write_text(yaml.safe_dump({"mesh": "foil.su2", "box": {"points": [6, 2]}, "changes": [{"twist": 1.0}],
                                      "constraints": [{"thickness": {"chord": [0.5], "span": [0.5]}}]}))
    assert_clean_failure(run_ffd("constraints", str(design)), 2, "foil.yaml", "constraints[0].thickness.span",
                         "2D")


def test_load_design_keeps_them(case):
    _, design = case
    d = load_design(design)
    assert d.data["constraints"] == CONSTRAINTS
    with pytest.raises(InputError):
        DesignModel.from_file(design).set_values(np.full(len(DesignModel.from_file(design).names), np.nan))
