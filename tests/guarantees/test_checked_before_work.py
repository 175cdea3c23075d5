"""Bad input is refused before any work, in one line naming the file, the key path or line and
what was expected (exit 2): the design file (YAML, schema, ``--set``, values, sizes), the box options,
the lattice size, the environment. Nothing of the workspace is created or modified (``assert_hostile``).
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REPO, SAMPLES, assert_clean_failure, file_hash, run_ffd
from hostile import (
    assert_hostile,
    bad_design,
    bad_mesh,
    design_with,
    edit_design,
    ffd,
    mesh_lines,
    no_parts,
    snapshot,
)
from hypothesis import given, settings
from hypothesis import strategies as st

pytest_plugins = ["hostile"]        # the workspaces: fixtures ws, ws2


def test_empty_design(ws):
    assert_hostile(ws, ["deform", bad_design(ws, "empty.yaml", "")], 2, "empty", names=["empty.yaml"])


def test_whitespace_only_design(ws):
    assert_hostile(ws, ["deform", bad_design(ws, "blank.yaml", "\n  \n# nothing\n")], 2,
                   names=["blank.yaml"])


def test_non_yaml_design(ws):
    name = bad_design(ws, "broken.yaml", "mesh: vwing.su2\nchanges: [ {twist: \n  - : : ]\n")
    assert_hostile(ws, ["deform", name], 2, "YAML", names=["broken.yaml:"])


def test_binary_design(ws):
    (ws / "binary.yaml").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe garbage")
    assert_hostile(ws, ["deform", "binary.yaml"], 2, names=["binary.yaml"])


def test_yaml_alias_bomb(ws):
    """Found here: nine levels of nine aliases (a 'billion laughs' file of 12 lines) hung ffd."""
    lines = ["mesh: vwing.su2", "surface: wing", "a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    lines += ["changes: [{twist: {tip: 3}}]"]
    name = bad_design(ws, "laughs.yaml", "\n".join(lines) + "\n")
    t0 = time.perf_counter()
    assert_hostile(ws, ["deform", name], 2, "aliases", names=["laughs.yaml:"])
    assert time.perf_counter() - t0 < 30


def test_yaml_nested_too_deep(ws):
    """Found here: 5000 nested brackets crashed the YAML composer with RecursionError (exit 1)."""
    name = bad_design(ws, "deep.yaml", "mesh: vwing.su2\nchanges: " + "[" * 5000 + "]" * 5000 + "\n")
    assert_hostile(ws, ["deform", name], 2, "deep", names=["deep.yaml"])


def test_design_is_a_list(ws):
    name = bad_design(ws, "alist.yaml", "- mesh: vwing.su2\n- changes: []\n")
    assert_hostile(ws, ["deform", name], 2, names=["alist.yaml"])


def test_design_missing(ws):
    assert_hostile(ws, ["deform", "no_such_design.yaml"], 2, names=["no_such_design.yaml"])


def test_unknown_top_level_key(ws):
    name = edit_design(ws, "unknown_key.yaml", lambda d: d.update(meshh="vwing.su2"))
    assert_hostile(ws, ["deform", name], 2, names=["unknown_key.yaml:", "meshh"])


def test_unknown_change(ws):
    name = edit_design(ws, "unknown_change.yaml", lambda d: d["changes"].append({"warp": 3}))
    assert_hostile(ws, ["deform", name], 2, "warp", names=["unknown_change.yaml:", "changes[2]"])


def test_unknown_box_key(ws):
    name = edit_design(ws, "unknown_box.yaml", lambda d: d["box"].update(pionts=[6, 8, 2]))
    assert_hostile(ws, ["deform", name], 2, "pionts", names=["unknown_box.yaml:", "box"])


def test_change_with_two_kinds(ws):
    name = edit_design(ws, "two_kinds.yaml", lambda d: d["changes"][0].update(span=1.1))
    assert_hostile(ws, ["deform", name], 2, names=["two_kinds.yaml:", "changes[0]"])


def test_wrong_type_twist(ws):
    name = edit_design(ws, "twist_str.yaml", lambda d: d["changes"].__setitem__(0, {"twist": "lots"}))
    assert_hostile(ws, ["deform", name], 2, names=["twist_str.yaml:", "changes[0].twist"])


def test_wrong_type_points(ws):
    name = edit_design(ws, "points_str.yaml", lambda d: d["box"].__setitem__("points", "six"))
    assert_hostile(ws, ["deform", name], 2, names=["points_str.yaml:", "box.points"])


def test_wrong_length_points(ws):
    name = edit_design(ws, "points_len.yaml", lambda d: d["box"].__setitem__("points", [6, 8]))
    assert_hostile(ws, ["deform", name], 2, names=["points_len.yaml:", "box.points"])


def test_no_box_points_uses_the_default(ws):
    """Not hostile but a crash found here: a design without box.points takes the mesh's default."""
    name = edit_design(ws, "no_points.yaml", lambda d: d.__setitem__("box", {}))
    proc = ffd("deform", name, "--json", cwd=ws)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["lattice"] == [6, 8, 2]


def test_degree_too_high_without_points(ws):
    """box.degree checked against the default points of a 3D mesh: names the design file and line."""
    name = edit_design(ws, "degree_only.yaml", lambda d: d.__setitem__("box", {"degree": [3, 3, 3]}))
    assert_hostile(ws, ["deform", name], 2, names=["degree_only.yaml:", "box.degree"])


@pytest.mark.parametrize("points", [[6, 100_000_000, 2], [3000, 3000, 2]], ids=["1e8", "3000x3000"])
def test_absurd_lattice_size(ws, points):
    """Found here: box.points [6, 1e8, 2] ran for minutes, [3000, 3000, 2] ran out of memory (exit 1)."""
    name = edit_design(ws, f"points_{points[1]}.yaml", lambda d: d["box"].__setitem__("points", points))
    assert_hostile(ws, ["deform", name], 2, "at most", names=[f"points_{points[1]}.yaml:", "box.points"])


def test_absurd_lattice_size_box_command(ws):
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "wing", "--points", "6,100000000,2"], 2, "at most",
                   names=["vwing.su2"])


def test_surface_wrong_type(ws):
    name = edit_design(ws, "surface_num.yaml", lambda d: d.__setitem__("surface", 12))
    assert_hostile(ws, ["deform", name], 2, names=["surface_num.yaml:", "surface"])


def test_twist_list_wrong_length(ws):
    name = design_with(ws, "twist_len.yaml", [{"twist": [0, 1, 2]}])     # 8 sections
    assert_hostile(ws, ["deform", name], 2, "8", names=["twist_len.yaml", "changes[0].twist"])


def test_shape_list_wrong_length(ws):
    name = design_with(ws, "shape_len.yaml", [{"shape": {"upper": [0, 0.01, 0], "sections": "all"}}])
    assert_hostile(ws, ["deform", name], 2, "6", names=["shape_len.yaml", "changes[0].shape.upper"])


def test_shape_section_out_of_range(ws):
    name = design_with(ws, "shape_sec.yaml", [{"shape": {"upper": [0, .01, .01, .01, .01, 0],
                                                          "sections": [0, 99]}}])
    assert_hostile(ws, ["deform", name], 2, "99", names=["shape_sec.yaml", "changes[0].shape.sections"])


def test_twist_nan(ws):
    name = bad_design(ws, "twist_nan.yaml", "mesh: vwing.su2\nsurface: wing\nbox: {points: [6, 8, 2]}\n"
                      "changes:\n  - twist: {tip: .nan}\noutput: {mesh: out_nan.su2}\n")
    assert_hostile(ws, ["deform", name], 2, names=["twist_nan.yaml:5", "changes[0].twist.tip"])


def test_span_inf(ws):
    name = bad_design(ws, "span_inf.yaml", "mesh: vwing.su2\nsurface: wing\nbox: {points: [6, 8, 2]}\n"
                      "changes:\n  - span: .inf\noutput: {mesh: out_inf.su2}\n")
    assert_hostile(ws, ["deform", name], 2, names=["span_inf.yaml:5", "changes[0].span"])


def test_shape_nan_in_list(ws):
    name = bad_design(ws, "shape_nan.yaml", "mesh: vwing.su2\nsurface: wing\nbox: {points: [6, 8, 2]}\n"
                      "changes:\n  - shape:\n      upper: [0, .nan, 0, 0, 0, 0]\n"
                      "output: {mesh: out_snan.su2}\n")
    assert_hostile(ws, ["deform", name], 2, names=["shape_nan.yaml", "changes[0].shape.upper"])


@pytest.mark.parametrize("value", [0, -1.2])
def test_span_not_positive(ws, value):
    name = design_with(ws, f"span_{value}.yaml", [{"span": value}])
    assert_hostile(ws, ["deform", name], 2, names=[f"span_{value}.yaml:", "changes[0].span"])


@pytest.mark.parametrize("value", [0, -0.5])
def test_chord_not_positive(ws, value):
    name = design_with(ws, f"chord_{value}.yaml", [{"chord": {"tip": value}}])
    assert_hostile(ws, ["deform", name], 2, names=[f"chord_{value}.yaml:", "changes[0].chord"])


def test_chord_list_with_zero(ws):
    name = design_with(ws, "chord_zero_list.yaml", [{"chord": [1, 1, 1, 0, 1, 1, 1, 1]}])
    assert_hostile(ws, ["deform", name], 2, names=["chord_zero_list.yaml", "changes[0].chord"])


@pytest.mark.parametrize("change", [{"sweep": 90}, {"dihedral": -88}], ids=["sweep", "dihedral"])
def test_shear_to_ninety_degrees(ws, change):
    """A shear angle that reaches +-90 degrees is refused (found here: the message named no file)."""
    kind = next(iter(change))
    name = design_with(ws, f"{kind}_90.yaml", [{"twist": {"tip": 2}}, change])
    assert_hostile(ws, ["deform", name], 2, "85", names=[f"{kind}_90.yaml:", f"changes[1].{kind}"])


def test_random_shape_amplitude_overflows(ws):
    """Found here: an amplitude of 1e308 crashed numpy's uniform draw (exit 1)."""
    name = design_with(ws, "random_huge.yaml", [{"shape": {"random": 1e308, "seed": 1}}])
    assert_hostile(ws, ["deform", name], 2, names=["random_huge.yaml:", "changes[0].shape.random"])


@pytest.mark.parametrize("change", [{"chord": {"tip": 1e300}}, {"span": 1e300},
                                   {"shape": {"upper": [0, 1e300, 0, 0, 0, 0]}}],
                         ids=["chord", "span", "shape"])
def test_finite_but_overflowing_values(ws, change):
    """Finite values so large that coordinates overflow: refused by the gate, even with --force
    (found here: chord 1e300 crashed in an SVD with exit 1, and --force would have written inf)."""
    kind = next(iter(change))
    name = design_with(ws, f"overflow_{kind}.yaml", [change])
    line = assert_hostile(ws, ["deform", name, "--force"], 3, names=[f"overflow_{kind}.yaml"])
    assert "nothing was written" in line


def test_twist_single_number_in_3d(ws):
    """A 3D twist of one number would move the root section without naming it: refused."""
    name = design_with(ws, "twist_scalar.yaml", [{"twist": 5}])
    assert_hostile(ws, ["deform", name], 2, names=["twist_scalar.yaml", "changes[0].twist"])


def test_2d_design_on_3d_points(ws):
    name = edit_design(ws, "points_2d.yaml", lambda d: d["box"].__setitem__("points", [6, 2]))
    assert_hostile(ws, ["deform", name], 2, names=["points_2d.yaml", "box.points"])


# 2D-only rules on the 2D config: span, sweep and dihedral do not exist; twist/chord are one number.
def _airfoil_design(ws: Path, name: str, change) -> str:
    data = yaml.safe_load((REPO / "configs" / "naca0012_s1223.yaml").read_text())
    data["mesh"] = str(SAMPLES / "naca0012_2d.su2")
    data["changes"] = [change]
    data["output"] = {"mesh": f"out_{Path(name).stem}.su2", "lattice": f"out_{Path(name).stem}_lattice.vtk"}
    (ws / name).write_text(yaml.safe_dump(data, sort_keys=False))
    return name


@pytest.mark.parametrize("change", [{"span": 1.1}, {"sweep": 5}, {"dihedral": -3},
                                    {"twist": [0, 1, 2]}, {"chord": {"tip": 0.8}}],
                         ids=["span", "sweep", "dihedral", "twist_list", "chord_tip"])
def test_3d_change_on_2d_config(ws, change):
    kind = next(iter(change))
    name = _airfoil_design(ws, f"airfoil_{kind}_{type(change[kind]).__name__}.yaml", change)
    mesh_hash = file_hash(SAMPLES / "naca0012_2d.su2")
    assert_hostile(ws, ["deform", name], 2, names=[name, f"changes[0].{kind}"])
    assert file_hash(SAMPLES / "naca0012_2d.su2") == mesh_hash


def test_set_unknown_key(ws):
    assert_hostile(ws, ["deform", "good.yaml", "--set", "changes.0.twist.tipp=12"], 2, "tipp",
                   names=["good.yaml"])


def test_set_unknown_top_key(ws):
    assert_hostile(ws, ["deform", "good.yaml", "--set", "nonsense=1"], 2, "nonsense", names=["good.yaml"])


def test_set_index_out_of_range(ws):
    assert_hostile(ws, ["deform", "good.yaml", "--set", "changes.7.twist.tip=12"], 2, names=["good.yaml"])


def test_set_without_equals(ws):
    assert_hostile(ws, ["deform", "good.yaml", "--set", "changes.0.twist.tip"], 2, "KEY=VALUE",
                   names=["good.yaml"])


def test_set_wrong_type(ws):
    assert_hostile(ws, ["deform", "good.yaml", "--set", "changes.0.twist.tip=abc"], 2,
                   names=["good.yaml", "changes[0].twist.tip"])


def test_set_nan(ws):
    assert_hostile(ws, ["deform", "good.yaml", "--set", "changes.1.chord.tip=.nan"], 2,
                   names=["good.yaml", "changes[1].chord.tip"])


def test_set_alias_bomb(ws):
    """Found here: a --set value that is an alias bomb hung ffd; a deeply nested one crashed."""
    bomb = "[&a0 [1,1,1,1,1,1,1,1,1]"
    bomb += "".join(f", &a{i} [{','.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 9)) + "]"
    assert_hostile(ws, ["deform", "good.yaml", "--set", f"changes.0.twist.tip={bomb}"], 2, "aliases",
                   names=["good.yaml", "changes.0.twist.tip"])
    for levels in (100, 3000):      # past the depth limit; past the parser's recursion (either is "deep")
        deep = "[" * levels + "]" * levels
        assert_hostile(ws, ["deform", "good.yaml", "--set", f"changes.0.twist.tip={deep}"], 2, "deep",
                       names=["good.yaml", "changes.0.twist.tip"])


def test_box_too_few_points(ws):
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "wing", "--points", "1,8,2"], 2)


def test_box_points_not_numbers(ws):
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "wing", "--points", "6,x,2"], 2)


def test_fit_on_3d_design(ws):
    assert_hostile(ws, ["fit", "good.yaml", "--target", str(SAMPLES / "s1223.dat")], 2, names=["good.yaml"])


@pytest.mark.parametrize("args,code", [
    (["deform", "empty.yaml"], 2),
    (["deform", "good.yaml", "--set", "changes.0.twist.tipp=12"], 2),
    (["inspect", "badelem.su2"], 2),
    (["deform", "good.yaml", "-o", "vwing.su2"], 2),
], ids=["empty_design", "set_unknown", "element_missing_point", "output_is_input"])
def test_subprocess_smoke(ws, args, code):
    """A few cases in a fresh interpreter (the console script's own error handling). Their inputs are
    made here (they were made by earlier cases when every case lived in one module)."""
    if not (ws / "empty.yaml").exists():
        bad_design(ws, "empty.yaml", "")
    if not (ws / "badelem.su2").exists():
        lines = mesh_lines(ws)
        parts = lines[5].split()
        parts[3] = "99999"
        lines[5] = "\t".join(parts) + "\n"
        bad_mesh(ws, "badelem.su2", lines)
    assert_hostile(ws, args, code, subprocess_run=True)


@pytest.mark.parametrize("points", ["256,256,256", "64,64,16"])
def test_lattice_total_refused_before_any_work(ws2, points):
    """Found: --points 256,256,256 (each within 'at most 256') grew to 23.8 GB and was OOM-killed.
    The mesh here is garbage: refused before it is read (and before the heavy imports)."""
    (ws2 / "garbage_box.su2").write_bytes(b"NDIME= 3\nnot a mesh\n")
    assert_hostile(ws2, ["box", "garbage_box.su2", "--surface", "wing", "--points", points], 2, "at most", "in all",
                   names=["garbage_box.su2", "--points"])


def test_lattice_total_in_a_design_names_the_line(ws2):
    import yaml

    data = yaml.safe_load((ws2 / "good.yaml").read_text())
    data["box"]["points"] = [200, 200, 2]
    data["mesh"] = "garbage_box.su2"                # refused when the design is loaded, before the mesh is read
    (ws2 / "garbage_box.su2").write_bytes(b"NDIME= 3\nnot a mesh\n")
    (ws2 / "big_lattice.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    assert_hostile(ws2, ["deform", "big_lattice.yaml"], 2, "at most", names=["big_lattice.yaml:", "box.points"])


def test_box_memory_estimate():
    from ffdcli.errors import InputError
    from ffdcli.lattice.limits import box_memory, check_box_memory

    small = box_memory((6, 8, 2), (3, 3, 1), 10_000)
    assert small < 50 * 2**20
    assert box_memory((6, 8, 2), (5, 5, 1), 10_000) > box_memory((6, 8, 2), (3, 3, 1), 10_000)
    with pytest.raises(InputError, match="needs about .* GB of memory, and 1.0 GB is available"):
        check_box_memory((30, 30, 30), (5, 5, 5), 10_000_000, available=2**30)
    assert check_box_memory((6, 8, 2), (3, 3, 1), 10_000, available=2**30) == small


@pytest.mark.parametrize("args", [["plot", "good.yaml", "-o", "mpl.png"],
                                  ["deform", "good.yaml", "-o", "mpl.su2", "--plot"]], ids=["plot", "deform"])
def test_bad_matplotlib_backend_in_the_environment(ws2, args):
    """Found: ``MPLBACKEND=Nonsense ffd plot`` was 'a bug in ffd'."""
    before = snapshot(ws2)
    proc = run_ffd(*args, cwd=ws2, env={"MPLBACKEND": "Nonsense"})
    assert_clean_failure(proc, 2, "MPLBACKEND", "Nonsense", "environment")
    assert "bug" not in proc.stderr
    assert snapshot(ws2) == before and no_parts(ws2) == []


@pytest.mark.parametrize("text,value", [("1e-05", 1e-05), ("1e1", 10.0), ("-2E+1", -20.0), ("1.5e1", 15.0),
                                        (".5", 0.5), ("7", 7)])
def test_numbers_as_str_and_printf_write_them(ws2, text, value):
    """Found: --set changes.0.twist.tip=1e-05 (Python's str(), printf %g) was 'expected a number'."""
    from ffdcli.design import load_design

    d = load_design(ws2 / "good.yaml", overrides=[f"changes.0.twist.tip={text}"])
    got = d.changes_spec[0]["twist"]["tip"]
    assert got == value and type(got) is type(value)
    proc = ffd("deform", "good.yaml", "--set", f"changes.0.twist.tip={text}", "-o", "num.su2", "-q", cwd=ws2)
    assert proc.returncode == 0, proc.stderr
    for f in ("num.su2", "num_lattice.vtk"):
        (ws2 / f).unlink()


def test_exponent_numbers_in_the_design_file(ws2):
    text = (ws2 / "good.yaml").read_text().replace("tip: 5", "tip: 5e0").replace("tip: 0.8", "tip: 8e-1")
    (ws2 / "exp.yaml").write_text(text + "volume: {method: idw, threshold: 1e-2}\n")
    from ffdcli.design import load_design

    d = load_design(ws2 / "exp.yaml")
    assert d.changes_spec == [{"twist": {"tip": 5.0}}, {"chord": {"tip": 0.8}}] and d.volume["threshold"] == 0.01
    big = (ws2 / "good.yaml").read_text().replace("points:", "margin: 1e6\n  points:")
    (ws2 / "margin_big.yaml").write_text(big)
    line = assert_hostile(ws2, ["deform", "margin_big.yaml"], 2, names=["margin_big.yaml:", "box.margin"])
    assert "expected a number" not in line          # a number, refused for its range


@pytest.mark.parametrize("where", ["file", "set"])
def test_huge_integer_names_the_key(ws2, where):
    """Found: a 400-digit integer was 'internal error: OverflowError'."""
    huge = "9" * 400
    if where == "file":
        (ws2 / "huge.yaml").write_text((ws2 / "good.yaml").read_text().replace("tip: 5", f"tip: {huge}"))
        line = assert_hostile(ws2, ["deform", "huge.yaml"], 2, "400 digits",
                              names=["huge.yaml:", "changes[0].twist.tip"])
    else:
        line = assert_hostile(ws2, ["deform", "good.yaml", "--set", f"changes.0.twist.tip={huge}"], 2, "400 digits",
                              names=["good.yaml", "changes[0].twist.tip"])
    assert huge not in line and "Overflow" not in line


@pytest.mark.parametrize("name", ["vwing.su2", "mesh_named.yaml"])
def test_mesh_given_as_the_design_file(ws2, name):
    """Found: ``ffd deform wing.su2`` echoed the whole 11 MB mesh into the error message."""
    if name.endswith(".yaml"):
        (ws2 / name).write_bytes((ws2 / "vwing.su2").read_bytes())
    line = assert_hostile(ws2, ["deform", name], 2, "is a mesh (SU2)", "ffd init", names=[name])
    assert len(line) < 300 and "NELEM" not in line


def test_long_string_quoted_briefly(ws2):
    (ws2 / "longstr.yaml").write_text("mesh: " + "x" * 5000 + "\nchanges: 3\n")
    line = assert_hostile(ws2, ["deform", "longstr.yaml"], 2, names=["longstr.yaml"])
    assert len(line) < 400


def test_million_value_list_refused_quickly(ws2):
    """Found: refused after 38 s of parsing."""
    text = (ws2 / "good.yaml").read_text() + "extra: [" + ", ".join(["0"] * 1_000_000) + "]\n"
    (ws2 / "million.yaml").write_text(text)
    # "commas and lines": refused by counting separators, before the YAML parser sees the text
    assert_hostile(ws2, ["deform", "million.yaml"], 2, "more than", "commas and lines", names=["million.yaml"])
    assert_hostile(ws2, ["deform", "good.yaml", "--set", "changes.0.twist.tip=[" + ",".join(["1"] * 300_000) + "]"],
                   2, "more than", "commas and lines")


def test_sections_not_the_plane_of_a_2d_mesh(tmp_path):
    """Found (item 12): box.sections: xz on a 2D x-y mesh was caught only at write time, with a
    message about the (temporary) output file."""

    from conftest import SAMPLES

    shutil.copy(SAMPLES / "naca0012_2d.su2", tmp_path / "a.su2")
    (tmp_path / "s.yaml").write_text("mesh: a.su2\nbox: {sections: xz}\nchanges: [{twist: 2}]\n")
    line = assert_hostile(tmp_path, ["deform", "s.yaml"], 2, "not the plane", "xy", names=["s.yaml:2", "box.sections"])
    assert ".part" not in line


def test_imported_lattice_total_is_bounded(ws2):
    """The bound holds for a lattice given as a Plot3D file (``ffd box --from``) too."""
    from ffdcli.io.formats.plot3d import write_plot3d

    n = 40
    grid = np.stack(np.meshgrid(np.linspace(-1, 2, n), np.linspace(-1, 4, n), np.linspace(-1, 1, 21),
                                indexing="ij"), axis=-1)
    write_plot3d(ws2 / "big_box.xyz", [grid])
    assert_hostile(ws2, ["box", "vwing.su2", "--surface", "wing", "--from", "big_box.xyz"], 2, "at most",
                   names=["big_box.xyz"])
    (ws2 / "big_box.xyz").unlink()



# ----------------------------------------------------------------------------------------------
# Issue 29: the whole file is checked the same way by every command (bounds: included)
# ----------------------------------------------------------------------------------------------

BAD_BOUNDS = {
    "outside": ({"c0.twist": [-1, 1]}, "outside its bounds", "bounds.c0.twist"),
    "unknown": ({"c9.span": [0.5, 2]}, "no design variable", "bounds.c9.span"),
    "reversed": ({"c1.chord": {"lower": 2, "upper": 1}}, "above the upper", "bounds.c1.chord"),
    "not_numbers": ({"c0.twist": ["a", 1]}, "", "bounds.c0.twist"),
}
COMMANDS = {"deform": ["deform", "{d}", "-o", "out_b.su2"], "box": ["box", "{d}"],
            "plot": ["plot", "{d}", "-o", "b.png"], "vars": ["vars", "{d}"], "constraints": ["constraints", "{d}"],
            "jacobian": ["jacobian", "{d}", "-o", "b.npz"], "grad": ["grad", "{d}", "--sens", "good.yaml"]}


@pytest.mark.parametrize("bad", list(BAD_BOUNDS))
@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_command_checks_the_bounds_the_same_way(ws, command, bad):
    """The probe: deform, box and plot wrote a design whose value lies outside its bounds (or whose
    bounds name no variable, or run backwards) with exit 0, while vars, constraints and grad refused it."""
    spec, words, key = BAD_BOUNDS[bad]
    name = edit_design(ws, f"bounds_{bad}.yaml", lambda d: d.update(bounds=spec))
    args = [a.format(d=name) for a in COMMANDS[command]]
    line = assert_hostile(ws, args, 2, words, names=[f"{name}:", key])
    assert line.count("ffd: error:") == 1


# ----------------------------------------------------------------------------------------------
# Issue 29: a design whose variables cannot move anything is exit 2 naming the key
# ----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def body(tmp_path_factory):
    d = tmp_path_factory.mktemp("body")
    shutil.copyfile(SAMPLES / "wing_body.su2", d / "wing_body.su2")
    return d


def _body_design(folder, points, changes, root=None):
    box = {"points": list(points)} | ({"root": root} if root else {})
    text = yaml.safe_dump({"mesh": "wing_body.su2", "surface": "wing", "box": box, "changes": changes},
                          sort_keys=False)
    path = folder / f"body_{points[1]}_{root}_{abs(hash(text)) % 10**8}.yaml"
    path.write_text(text)
    return path


BODY_CHANGES = [[{"twist": {"tip": 4}}], [{"dihedral": 3}], [{"sweep": 5}], [{"chord": {"tip": 0.8}}],
                [{"span": 1.1}], [{"twist": {"tip": 0}}, {"dihedral": -2}]]


@pytest.mark.slow
@pytest.mark.parametrize("sections", [3, 4])
@pytest.mark.parametrize("changes", BODY_CHANGES, ids=lambda c: "+".join(next(iter(x)) for x in c))
def test_a_wing_on_a_body_whose_sections_are_all_frozen_is_refused(body, sections, changes):
    """The probe: ``box.points=[6,4,2]`` on the wing on a body deformed nothing with exit 0 (every
    section carries the junction). Every non-zero change is exit 2 naming its key and line."""
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design
    from ffdcli.errors import InputError

    path = _body_design(body, (6, sections, 2), changes)
    with pytest.raises(InputError) as e:
        load_run(load_design(path))
    k = next(i for i, c in enumerate(changes) if next(iter(c.values())) not in ({"tip": 0},))
    msg = str(e.value)
    assert f"{path.name}:" in msg and f"changes[{k}].{next(iter(changes[k]))}" in msg and "box.points" in msg, msg


@pytest.mark.slow
@pytest.mark.parametrize("changes", BODY_CHANGES[:3], ids=lambda c: "+".join(next(iter(x)) for x in c))
def test_a_root_at_the_wrong_end_is_refused_naming_box_root(body, changes):
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design
    from ffdcli.errors import InputError

    path = _body_design(body, (6, 10, 2), changes, root="max")
    with pytest.raises(InputError) as e:
        load_run(load_design(path))
    assert "box.root" in str(e.value) and f"{path.name}:" in str(e.value), str(e.value)


@pytest.mark.slow
def test_a_wing_on_a_body_with_free_sections_still_moves(body):
    """The control: enough sections, the root where the body is: the design moves the wing."""
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design

    run = load_run(load_design(_body_design(body, (6, 6, 2), [{"twist": {"tip": 4}}])))
    assert deform(run, check=False).max_displacement > 1e-3


@pytest.mark.slow
def test_the_probe_frozen_case_through_the_command_line(body):
    data = yaml.safe_load((REPO / "configs" / "wing_body.yaml").read_text())
    data["mesh"] = "wing_body.su2"
    data.pop("output")
    (body / "wb.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    proc = run_ffd("deform", "wb.yaml", "--set", "box.points=[6,4,2]", "-o", "wb_out.su2", "--json", cwd=body)
    assert_clean_failure(proc, 2, "wb.yaml:", "changes[0].twist")
    assert not (body / "wb_out.su2").exists()


# ----------------------------------------------------------------------------------------------
# Issue 29: every input error names the file, the line and the full key path
# ----------------------------------------------------------------------------------------------

TWIST_PROBLEMS = [({"tip": 1, "values": [1, 2]}, "values"), ({"root": 1}, "root"), ({"axis": 0.25}, None),
                  ({"tip": 1, "angle": 2}, "angle")]


@settings(max_examples=30, deadline=None, derandomize=True)
@given(n_comp=st.integers(1, 3), data=st.data())
def test_errors_inside_a_component_name_the_full_key_path_and_line(n_comp, data):
    """The probe: a twist error inside components[1] was reported as ``changes[0].twist`` with no line."""
    from ffdcli.design.validate import validate
    from ffdcli.design.yamlmap import load_yaml, yaml_lines
    from ffdcli.errors import InputError

    c = data.draw(st.integers(0, n_comp - 1))
    k = data.draw(st.integers(0, 2))
    bad, sub = data.draw(st.sampled_from(TWIST_PROBLEMS))
    comps = []
    for i in range(n_comp):
        changes = [{"span": 1.0}] * 3
        if i == c:
            changes = changes[:k] + [{"twist": bad}] + changes[k + 1:]
        comps.append({"name": f"part{i}", "surface": f"m{i}", "changes": changes})
    text = yaml.safe_dump({"mesh": "m.su2", "components": comps}, sort_keys=False)
    data_, lines = load_yaml(text), yaml_lines(text)
    with pytest.raises(InputError) as e:
        validate(data_, path="d.yaml", lines=lines)
    key = f"components[{c}].changes[{k}].twist"
    assert e.value.key in (key, f"{key}.{sub}"), (e.value.key, key)
    assert e.value.line is not None
    assert text.splitlines()[e.value.line - 1].strip().startswith(("- twist", "twist", "tip", "root", "values",
                                                                   "axis", "angle", "-")), (e.value.line, text)


# ----------------------------------------------------------------------------------------------
# Issue 29: thickness stations: the schema and the run agree
# ----------------------------------------------------------------------------------------------

@settings(max_examples=60, deadline=None, derandomize=True)
@given(x=st.one_of(st.sampled_from([0.0, 1.0, -0.0, 1e-300, 1 - 1e-16, 0.5, -1e-9, 1 + 1e-9]),
                   st.floats(-0.5, 1.5, allow_nan=False)), which=st.sampled_from(["chord", "span"]))
def test_thickness_stations_schema_and_run_agree(x, which):
    """The probe: chord stations 0 and 1 passed the schema (and the docs) and failed at run time, with a
    hint naming the trailing edge for chord 0. Now chord stations lie strictly inside (0, 1) for both."""
    import jsonschema

    from ffdcli.constraints.thickness import _fractions
    from ffdcli.design.schema import constraints_schema
    from ffdcli.errors import InputError

    item = {"thickness": {"chord": [0.5], "span": [0.5]}}
    item["thickness"][which] = [x]
    schema_ok = jsonschema.Draft202012Validator(constraints_schema()).is_valid([item])
    try:
        _fractions(item["thickness"], which, "constraints[0].thickness", lambda m, k: InputError(m, key=k))
        run_ok = True
    except InputError:
        run_ok = False
    assert schema_ok == run_ok
    assert schema_ok == ((0 < x < 1) if which == "chord" else (0 <= x <= 1))


@pytest.mark.parametrize("x", [0, 1])
def test_chord_station_at_an_edge_names_the_key_and_line(ws, x):
    name = edit_design(ws, f"chord_{x}.yaml", lambda d: d.update(
        constraints=[{"thickness": {"chord": [0.3, x], "span": [0.5]}}]))
    assert_hostile(ws, ["constraints", name], 2, "less than 1" if x else "greater than 0",
                   names=[f"{name}:", "constraints[0].thickness.chord[1]"])


def test_zz_the_workspace_is_as_it_was(ws):
    """Last (as in every module that runs cases in ``ws``): no case touched the mesh or left a .part file."""
    assert file_hash(ws / "vwing.su2") == (ws / "vwing.su2.sha256").read_text()
    assert not list(ws.rglob("*.part*"))
