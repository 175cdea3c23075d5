"""The Python API refuses what the command line refuses, with ffd's InputError and the same words.
"""

from __future__ import annotations

import numpy as np
import pytest
from hostile import error_line, ffd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest_plugins = ["hostile"]        # the workspaces: fixtures ws, ws2


def test_api_refuses_what_the_cli_refuses(ws2):
    from ffdcli.api import DesignModel
    from ffdcli.errors import InputError

    model = DesignModel.from_file(ws2 / "good.yaml")
    v0 = model.values.copy()
    chord = [i for i, n in enumerate(model.names) if ".chord" in n]
    for bad in (np.nan, np.inf, -np.inf):
        v = v0.copy()
        v[0] = bad
        with pytest.raises(InputError, match=model.names[0].replace("[", r"\[").replace("]", r"\]")):
            model.set_values(v)
    for bad in (0.0, -1.0):
        v = v0.copy()
        v[chord[-1]] = bad
        with pytest.raises(InputError):
            model.set_values(v)
    assert np.array_equal(model.values, v0)              # unchanged after every refusal
    with pytest.raises(InputError):
        model.surface_jvp(np.ones(model.n_vars + 1))
    with pytest.raises(InputError):
        model.surface_vjp(np.ones((3, 3)))
    with pytest.raises(InputError, match="list of KEY=VALUE"):
        DesignModel.from_file(ws2 / "good.yaml", "changes.0.twist.tip=3")



# ----------------------------------------------------------------------------------------------
# Issue 29: every invalid argument of the API is ffd's InputError, in the command line's words
# ----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def model(tmp_path_factory):
    from wingcase import write_design, write_volume_wing

    from ffdcli.api import DesignModel

    d = tmp_path_factory.mktemp("misuse")
    mesh = write_volume_wing(d)
    design = write_design(d, mesh, [{"twist": {"tip": 2}}, {"span": 1.05}],
                          extra={"constraints": [{"volume": {"lower": 0.9}}]})
    m = DesignModel.from_file(design)
    m.add_points("probe", m.surface_points()[:4])
    return m


NOT_NUMBERS = st.one_of(st.text(max_size=4), st.none(), st.just([None]), st.just([[1.0], [1.0, 2.0]]),
                        st.just(1j), st.just({"a": 1}), st.just(object()))
BAD_FLOATS = st.sampled_from([np.nan, np.inf, -np.inf])


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(bad=NOT_NUMBERS, method=st.sampled_from(["set_values", "surface_jvp", "surface_vjp", "mesh_vjp", "points_jvp",
                                                "points_vjp", "add_points", "set_values_dict"]))
def test_anything_that_is_not_numbers_is_an_input_error(model, bad, method):
    """The probe: set_values with a string or None raised raw Python exceptions."""
    from ffdcli.errors import InputError

    v0 = model.values.copy()
    call = {"set_values": lambda: model.set_values(bad), "surface_jvp": lambda: model.surface_jvp(bad),
            "surface_vjp": lambda: model.surface_vjp(bad), "mesh_vjp": lambda: model.mesh_vjp(bad),
            "points_jvp": lambda: model.points_jvp("probe", bad), "points_vjp": lambda: model.points_vjp("probe", bad),
            "add_points": lambda: model.add_points("bad", bad),
            "set_values_dict": lambda: model.set_values({model.names[0]: bad})}[method]
    with pytest.raises(InputError) as e:
        call()
    assert "expected" in str(e.value) or "must have shape" in str(e.value), str(e.value)
    assert np.array_equal(model.values, v0)


@settings(max_examples=30, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(bad=BAD_FLOATS, at=st.integers(0, 1), method=st.sampled_from(["surface_jvp", "points_jvp", "set_values"]))
def test_nan_and_infinity_are_input_errors(model, bad, at, method):
    from ffdcli.errors import InputError

    v = model.values.copy() if method == "set_values" else np.zeros(model.n_vars)
    v[at] = bad
    call = {"set_values": model.set_values, "surface_jvp": model.surface_jvp,
            "points_jvp": lambda x: model.points_jvp("probe", x)}[method]
    with pytest.raises(InputError, match="finite"):
        call(v)


BAD_CONSTRAINTS = [
    ([{"volume": {"lower": "abc"}}], "constraints[0].volume.lower"),
    ([{"bulk": {}}], "constraints[0].bulk"),
    ("volume", "constraints"),
    ([{"thickness": {"chord": [0], "span": [0.5]}}], "constraints[0].thickness.chord[0]"),
    ([{"thickness": {"chord": [0.5], "span": [2]}}], "constraints[0].thickness.span[0]"),
    ([{"volume": {"lower": float("nan")}}], "constraints[0].volume.lower"),
    ([{"volume": {}, "le_te": {}}], "constraints[0]"),
]


@pytest.mark.parametrize("specs,key", BAD_CONSTRAINTS, ids=[k for _, k in BAD_CONSTRAINTS])
def test_set_constraints_speaks_as_the_command_line(model, ws2, specs, key):
    """The API's error names the same key with the same words as ``ffd constraints`` on a design file
    holding the same ``constraints:`` (the probe: raw exceptions for a bad value)."""
    import yaml

    from ffdcli.errors import InputError

    with pytest.raises(InputError) as e:
        model.set_constraints(specs)
    assert e.value.key == key, (e.value.key, str(e.value))
    data = yaml.safe_load((ws2 / "good.yaml").read_text())
    data["constraints"] = specs
    (ws2 / "api_vs_cli.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    proc = ffd("constraints", "api_vs_cli.yaml", cwd=ws2)
    line = error_line(proc)
    assert f"{key}: {e.value.message}" in line, (line, str(e.value))


@pytest.mark.parametrize("component", [1, -1, 7, "wing", 0.0, None, True])
def test_set_constraints_of_a_component_that_does_not_exist(model, component):
    from ffdcli.errors import InputError

    with pytest.raises(InputError, match="does not exist"):
        model.set_constraints([{"volume": {}}], component=component)
