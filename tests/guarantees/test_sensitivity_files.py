"""Sensitivity files (``ffd grad --sens``): a file that does not belong to the mesh, or that cannot be
read as one table of numbers, is refused with the file, the line and what was expected (exit 2).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_clean_failure, run_ffd
from hostile import assert_hostile, ffd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from wingcase import write_design

pytest_plugins = ["hostile"]        # the workspaces: fixtures ws, ws2


def _sens_csv(ws: Path, name: str, ids) -> str:
    rows = ['"PointID","x","y","z","Sensitivity_x","Sensitivity_y","Sensitivity_z"']
    rows += [f"{i},0,0,0,1,0,0" for i in ids]
    (ws / name).write_text("\n".join(rows) + "\n")
    return name


def test_sens_point_not_in_mesh(ws):
    sens = _sens_csv(ws, "sens_missing.csv", ids=[0, 1, 999999])
    assert_hostile(ws, ["grad", "good.yaml", "--sens", sens], 2, "999999", names=["sens_missing.csv:4"])


def test_sens_coordinates_match_nothing(ws):
    (ws / "sens_far.dat").write_text("0 0 0 1 0 0\n100 100 100 1 0 0\n")
    assert_hostile(ws, ["grad", "good.yaml", "--sens", "sens_far.dat"], 2, names=["sens_far.dat"])


def test_sens_file_missing(ws):
    assert_hostile(ws, ["grad", "good.yaml", "--sens", "nothing.csv"], 2, names=["nothing.csv"])


def test_sens_not_numbers(ws):
    (ws / "sens_text.csv").write_text("PointID,Sensitivity_x,Sensitivity_y,Sensitivity_z\n0,a,b,c\n")
    assert_hostile(ws, ["grad", "good.yaml", "--sens", "sens_text.csv"], 2, names=["sens_text.csv:2"])


def test_sens_ragged_rows(ws):
    (ws / "sens_ragged.csv").write_text("PointID,Sensitivity_x,Sensitivity_y,Sensitivity_z\n0,1,0,0\n1,1\n")
    assert_hostile(ws, ["grad", "good.yaml", "--sens", "sens_ragged.csv"], 2, names=["sens_ragged.csv:3"])


def test_sensitivity_missing_surface_nodes_is_an_error(tmp_path):
    """A surface sensitivity file that leaves out some wing nodes is an error, not a partial gradient."""
    from wingcase import write_surface_wing

    from ffdcli.api import DesignModel

    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"span": 1.1}])
    model = DesignModel.from_file(design)
    X = model.surface_points()
    rows = np.c_[X, np.ones_like(X)][:-3]
    np.savetxt(tmp_path / "part.dat", rows, fmt="%.17g")
    assert_clean_failure(run_ffd("grad", str(design), "--sens", str(tmp_path / "part.dat")), 2, "part.dat",
                         "no row for 3")



# ----------------------------------------------------------------------------------------------
# Issue 29: a file that does not belong to the mesh, or whose table is not one table, in every form
# ----------------------------------------------------------------------------------------------

RNG_POINTS = np.random.default_rng(29).uniform(-1.0, 1.0, (40, 3)) * [4.0, 2.0, 0.5]
DIAG = float(np.linalg.norm(np.ptp(RNG_POINTS, axis=0)))
TOL = 1e-6 * DIAG


def _table(points, ids, *, form: str, sep: str, quote: bool, bom: bool, upper: bool, values=None,
           header_names=None) -> str:
    """A sensitivity file of ``points[ids]`` in one of the accepted forms (``id``: SU2's CSV with
    PointID and coordinates; ``xyz``: the unordered rows, with a header or not)."""
    values = np.arange(len(ids) * 3, dtype=float).reshape(-1, 3) * 0.01 + 1.0 if values is None else values
    q = '"' if quote else ""
    if form == "id":
        names = header_names or ["PointID", "x", "y", "z", "Sensitivity_x", "Sensitivity_y", "Sensitivity_z"]
        rows = [[str(i), *(f"{v:.17g}" for v in points[i]), *(f"{v:.17g}" for v in g)] for i, g in zip(ids, values)]
    else:
        names = header_names or ["x", "y", "z", "dJdx", "dJdy", "dJdz"]
        rows = [[*(f"{v:.17g}" for v in points[i]), *(f"{v:.17g}" for v in g)] for i, g in zip(ids, values)]
    head = sep.join(q + (n.upper() if upper else n) + q for n in names)
    text = "\n".join([head] + [sep.join(r) for r in rows]) + "\n"
    return ("\ufeff" if bom else "") + text


FORMS = st.fixed_dictionaries({"form": st.sampled_from(["id", "xyz"]), "sep": st.sampled_from([",", " ", ", ", "\t"]),
                               "quote": st.booleans(), "bom": st.booleans(), "upper": st.booleans()})


def _read(tmp_path, text, name="sens.csv", tol=None):
    from ffdcli.io.formats.sensitivity import read_sensitivity

    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return read_sensitivity(p, RNG_POINTS, 3, tol=tol)


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(f=FORMS, ids=st.lists(st.integers(0, 39), min_size=2, max_size=12, unique=True))
def test_every_accepted_form_reads_the_same_values(tmp_path, f, ids):
    """A BOM, quotes, separators and header case do not change what is read."""
    sens = _read(tmp_path, _table(RNG_POINTS, ids, **f))
    order = np.argsort(sens.ids)
    assert sorted(sens.ids.tolist()) == sorted(ids)
    expect = (np.arange(len(ids) * 3, dtype=float).reshape(-1, 3) * 0.01 + 1.0)[np.argsort(ids)]
    assert np.allclose(sens.values[order], expect)


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(f=FORMS, ids=st.lists(st.integers(0, 39), min_size=3, max_size=10, unique=True), data=st.data())
def test_a_file_of_another_mesh_is_refused_in_both_forms(tmp_path, f, ids, data):
    """Rows whose coordinates stand off their node by more than the tolerance (another design's or
    another mesh's file): refused with the distance, the tolerance and the line, PointID rows too."""
    from ffdcli.errors import InputError

    far = data.draw(st.lists(st.sampled_from(range(len(ids))), min_size=1, max_size=len(ids), unique=True))
    off = data.draw(st.floats(10 * TOL, 9.0))
    moved = RNG_POINTS.copy()
    for k in far:
        moved[ids[k]] = moved[ids[k]] + off * np.array([0.6, -0.8, 0.0])
    with pytest.raises(InputError) as e:
        _read(tmp_path, _table(moved, ids, **f))
    msg = str(e.value)
    assert "sens.csv:" in msg and "tolerance" in msg and f"{TOL:.3g}" in msg, msg
    assert f"{off:.3g}" in msg or "worst" in msg, msg
    # within --tolerance the same file is read
    if f["form"] == "id":
        assert len(_read(tmp_path, _table(moved, ids, **f), tol=2 * off).ids) == len(ids)


@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(f=FORMS, twice=st.sampled_from(["sensitivity_x", "sensitivity_y", "sensitivity_z", "x", "pointid"]))
def test_a_column_named_twice_is_an_error(tmp_path, f, twice):
    from ffdcli.errors import InputError

    names = ["PointID", "x", "y", "z", "Sensitivity_x", "Sensitivity_y", "Sensitivity_z"]
    names.append(twice if f["upper"] else twice.title())
    text = _table(RNG_POINTS, [0, 1, 2], **{**f, "form": "id"}, header_names=names)
    text = "\n".join(ln + (f["sep"] + "0" if k else "") for k, ln in enumerate(text.split("\n")) if ln) + "\n"
    with pytest.raises(InputError) as e:
        _read(tmp_path, text)
    assert "sens.csv:1:" in str(e.value) and "twice" in str(e.value) and "columns" in str(e.value), str(e.value)


@settings(max_examples=30, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(f=FORMS, row=st.integers(0, 5), keep=st.integers(1, 6))
def test_the_expected_column_count_is_the_headers(tmp_path, f, row, keep):
    """A row shorter (or longer) than the header: exit 2 naming that row's line and both counts; an
    empty field is named where it is, not on the next row."""
    from ffdcli.errors import InputError

    text = _table(RNG_POINTS, list(range(6)), **{**f, "form": "id"})
    lines = text.split("\n")
    sep = f["sep"]
    fields = lines[row + 1].split(sep.strip() or None) if sep.strip() else lines[row + 1].split()
    lines[row + 1] = sep.join(fields[:keep])
    with pytest.raises(InputError) as e:
        _read(tmp_path, "\n".join(lines))
    assert str(e.value).startswith(f"{tmp_path / 'sens.csv'}:{row + 2}: the header has 7 columns, this row has {keep}")
    if "," in sep:                          # an empty field in a comma-separated row
        lines = text.split("\n")
        parts = lines[row + 1].split(",")
        parts[keep] = ""
        lines[row + 1] = ",".join(parts)
        with pytest.raises(InputError) as e:
            _read(tmp_path, "\n".join(lines))
        assert f"sens.csv:{row + 2}: empty field in column {keep + 1}" in str(e.value), str(e.value)


@settings(max_examples=20, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(f=FORMS, ids=st.lists(st.integers(0, 39), min_size=2, max_size=8, unique=True), data=st.data())
def test_a_node_given_twice_names_both_lines(tmp_path, f, ids, data):
    from ffdcli.errors import InputError

    k = data.draw(st.integers(0, len(ids) - 1))
    ids2 = ids + [ids[k]]
    with pytest.raises(InputError) as e:
        _read(tmp_path, _table(RNG_POINTS, ids2, **f))
    assert f"lines {k + 2} and {len(ids2) + 1} both give mesh node {ids[k]}" in str(e.value), str(e.value)


def test_the_header_has_7_columns_this_row_has_4_through_the_command_line(ws):
    """The probe's case: exit 2 and ``file:2: the header has 7 columns, this row has 4`` (was an
    IndexError, exit 1)."""
    (ws / "sens_short.csv").write_text('"PointID","x","y","z","Sensitivity_x","Sensitivity_y","Sensitivity_z"\n'
                                       "0,0,0,0\n1,0,0,0\n")
    assert_hostile(ws, ["grad", "good.yaml", "--sens", "sens_short.csv"], 2,
                   "sens_short.csv:2: the header has 7 columns, this row has 4")


def _surface_rows(ws, name, *, scale=1.0, shift=0.0, twice=None):
    """The wing's surface nodes of the deformed good design, PointID rows with coordinates."""
    from ffdcli.api import DesignModel

    model = DesignModel.from_file(ws / "good.yaml")
    X = model.mesh_points()
    ids = model.surface_ids
    cols = ["PointID", "x", "y", "z", "Sensitivity_x", twice or "Sensitivity_y", "Sensitivity_z"]
    rows = [",".join(cols)] + [f"{i},{X[i, 0] + shift:.17g},{X[i, 1]:.17g},{X[i, 2]:.17g},{scale:g},{scale:g},"
                               f"{scale:g}" for i in ids]
    (ws / name).write_text("\n".join(rows) + "\n")
    return name


@pytest.mark.parametrize("shift", [0.1, 9.0])
def test_point_id_rows_of_another_design_are_refused(ws, shift):
    """The probe: PointID rows 0.1 or 9 mesh units off were accepted (a wrong gradient, exit 0)."""
    name = _surface_rows(ws, f"sens_shift{shift:g}.csv", shift=shift)
    assert_hostile(ws, ["grad", "good.yaml", "--sens", name], 2, "tolerance", f"worst {shift:.3g}", names=[name])


def test_sensitivity_x_twice_is_refused(ws):
    """The probe: ``Sensitivity_x`` twice made the last one count (gradient 2.9e-9 -> -17.99, exit 0)."""
    name = _surface_rows(ws, "sens_twice.csv", twice="Sensitivity_x")
    assert_hostile(ws, ["grad", "good.yaml", "--sens", name], 2, "twice", names=[f"{name}:1"])


@pytest.mark.parametrize("value", ["1e308", "-1.7e308"])
@pytest.mark.parametrize("output", [False, True])
def test_an_overflowing_gradient_is_an_error_never_nan(ws, value, output):
    """The probe: 1e308 sensitivities gave NaN gradients with exit 0, ``NaN`` in --json and -o (invalid
    JSON) and a raw RuntimeWarning. Now: exit 2 naming the file, nothing written, no warning."""
    name = _surface_rows(ws, f"sens_huge{value}.csv", scale=float(value))
    args = ["grad", "good.yaml", "--sens", name, "--json"] + (["-o", "grad_huge.json"] if output else [])
    proc = ffd(*args, cwd=ws, subprocess_run=True)
    assert_clean_failure(proc, 2, name, "overflows")
    assert "Warning" not in proc.stderr, proc.stderr
    assert json.loads(proc.stdout)["exit_code"] == 2
    assert not (ws / "grad_huge.json").exists()


@settings(max_examples=60, deadline=None, derandomize=True)
@given(obj=st.recursive(st.one_of(st.floats(), st.integers(), st.text(max_size=5), st.none(), st.booleans()),
                        lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                st.dictionaries(st.text(max_size=4), inner, max_size=4)),
                        max_leaves=20))
def test_the_json_writer_never_writes_nan_or_infinity(obj):
    """Every JSON ffd writes goes through one writer, whose output is strict JSON (non-finite -> null)."""
    from ffdcli.io.jsontext import to_json

    def refuse(name):
        raise AssertionError(f"{name} in the JSON")

    text = to_json({"a": obj, "np": np.array([1.0, np.nan, np.inf]), "s": np.float64("-inf")}, indent=1)
    back = json.loads(text, parse_constant=refuse)
    assert back["np"] == [1.0, None, None] and back["s"] is None


def test_json_summary_without_coordinates_is_strict_json(ws):
    """A sensitivity file without coordinates has no match distance: null in --json, never NaN."""
    from ffdcli.api import DesignModel

    model = DesignModel.from_file(ws / "good.yaml")
    rows = ["PointID,Sensitivity_x,Sensitivity_y,Sensitivity_z"] + [f"{i},1,0,0" for i in model.surface_ids]
    (ws / "sens_nocoords.csv").write_text("\n".join(rows) + "\n")
    proc = ffd("grad", "good.yaml", "--sens", "sens_nocoords.csv", "--json", cwd=ws)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout, parse_constant=lambda c: pytest.fail(f"{c} in the JSON"))
    assert summary["worst_match_distance"] is None
