"""Hostile input: every bad input fails loudly and cleanly, never half-writes, never loses data.

Each case runs one ``ffd`` command on a bad input inside a shared workspace (a small volume wing, a
good design and the outputs and cache of one good run) and asserts:

- the exit status (2 bad input, 3 quality gate) and exactly one ``ffd: error:`` line that names the
  file and the problem (and the YAML key path or line), with no Python traceback;
- no file of the workspace is created or modified (the input mesh, the good outputs, the cache),
  except a new, complete cache file of a mesh that was read successfully; no ``.part`` file remains.

The last test of the module runs the good design again: it must reuse the cache (not poisoned by
any of the cases) and reproduce the first output bit for bit.

Cases run the command line in this interpreter (``ffdcli.cli.main`` with the real argument parsing
and error handling, as the console script does) because a fresh interpreter per case would cost a
second each on a loaded machine; ``test_subprocess_smoke`` runs a few of them in a real subprocess,
and ``FFD_HOSTILE_SUBPROCESS=1`` runs all of them that way.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REPO, SAMPLES, assert_clean_failure, file_hash, run_ffd
from wingcase import write_design, write_volume_wing

SUBPROCESS = os.environ.get("FFD_HOSTILE_SUBPROCESS") == "1"
GOOD = [{"twist": {"tip": 5}}, {"chord": {"tip": 0.8}}]


# ----------------------------------------------------------------------------------------------
# Running the command line and checking the workspace
# ----------------------------------------------------------------------------------------------

def ffd_inproc(*args, cwd: Path) -> subprocess.CompletedProcess:
    """``ffd ARGS`` through :func:`ffdcli.cli.main` in this interpreter (same parsing and errors)."""
    from ffdcli.cli import main

    out, err = io.StringIO(), io.StringIO()
    code = None
    with contextlib.chdir(cwd), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([str(a) for a in args])
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
        except Exception:  # noqa: BLE001  (a crash past main's handlers: show it as a traceback)
            import traceback

            err.write(traceback.format_exc())
            code = 1
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


def ffd(*args, cwd: Path, subprocess_run: bool = False) -> subprocess.CompletedProcess:
    if SUBPROCESS or subprocess_run:
        return run_ffd(*args, cwd=cwd, timeout=300)
    return ffd_inproc(*args, cwd=cwd)


def snapshot(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): file_hash(p) for p in sorted(folder.rglob("*")) if p.is_file()}


def error_line(proc, usage: bool = False) -> str:
    prefix = "Error:" if usage else "ffd: error:"
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith(prefix)]
    assert len(lines) == 1, proc.stderr
    return lines[0]


def assert_hostile(ws: Path, args, code: int, *texts: str, names=(), subprocess_run: bool = False,
                   usage: bool = False):
    """Run ``ffd ARGS`` in ``ws`` and check the clean failure and the untouched workspace.

    ``texts`` must appear in the error line; ``names`` are file names (or key paths / lines) that the
    message must name. ``usage``: a command-line usage error, reported by click as its usage text and
    one ``Error:`` line (exit 2) instead of ``ffd: error:``. Returns the error line."""
    before = snapshot(ws)
    proc = ffd(*args, cwd=ws, subprocess_run=subprocess_run)
    if usage:
        assert proc.returncode == code and "Traceback" not in proc.stderr, (proc.returncode, proc.stderr)
    else:
        assert_clean_failure(proc, code)
    line = error_line(proc, usage)
    for t in (*texts, *names):
        assert t in line, (t, line)
    after = snapshot(ws)
    changed = sorted(k for k in before if after.get(k) != before[k])
    assert not changed, f"modified or removed: {changed}\n{line}"
    created = sorted(set(after) - set(before))
    assert not [c for c in created if ".part" in c], created
    for c in created:   # only the cache of a mesh that was read successfully, and a complete one
        assert c.endswith(".ffdcache.npz"), f"created {c}: {line}"
        with np.load(ws / c) as z:
            assert "header" in z.files
    return line


# ----------------------------------------------------------------------------------------------
# The workspace: a small volume wing, a good design, one good run (its output and cache)
# ----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    d = tmp_path_factory.mktemp("hostile")
    mesh = write_volume_wing(d)
    write_design(d, mesh, GOOD, name="good.yaml")
    proc = run_ffd("deform", "good.yaml", "--json", cwd=d)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["from_cache"] is False
    shutil.copyfile(d / "out_good.su2", d / "ref_out.su2")
    (d / "vwing.su2.sha256").write_text(file_hash(mesh))
    return d


def bad_design(ws: Path, name: str, text: str) -> str:
    (ws / name).write_text(text)
    return name


def design_with(ws: Path, name: str, changes=None, **extra) -> str:
    write_design(ws, ws / "vwing.su2", GOOD if changes is None else changes, name=name, extra=extra or None)
    return name


def edit_design(ws: Path, name: str, edit) -> str:
    """The good design, edited by ``edit(data)``, written as ``name``."""
    data = yaml.safe_load((ws / "good.yaml").read_text())
    edit(data)
    data["output"] = {"mesh": f"out_{Path(name).stem}.su2", "lattice": f"out_{Path(name).stem}_lattice.vtk"}
    (ws / name).write_text(yaml.safe_dump(data, sort_keys=False))
    return name


# ----------------------------------------------------------------------------------------------
# Design files
# ----------------------------------------------------------------------------------------------

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


# ----------------------------------------------------------------------------------------------
# --set
# ----------------------------------------------------------------------------------------------

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
    deep = "[" * 3000 + "]" * 3000
    assert_hostile(ws, ["deform", "good.yaml", "--set", f"changes.0.twist.tip={deep}"], 2, "deep",
                   names=["good.yaml", "changes.0.twist.tip"])


# ----------------------------------------------------------------------------------------------
# Meshes
# ----------------------------------------------------------------------------------------------

def mesh_lines(ws: Path) -> list[str]:
    return (ws / "vwing.su2").read_text().splitlines(keepends=True)


def bad_mesh(ws: Path, name: str, lines) -> str:
    (ws / name).write_text("".join(lines))
    return name


def _find(lines, prefix):
    return next(i for i, ln in enumerate(lines) if ln.startswith(prefix))


def test_missing_mesh_in_design(ws):
    name = edit_design(ws, "missing_mesh.yaml", lambda d: d.__setitem__("mesh", "nowhere.su2"))
    assert_hostile(ws, ["deform", name], 2, "nowhere.su2", names=["missing_mesh.yaml", "mesh"])


def test_missing_mesh_inspect(ws):
    assert_hostile(ws, ["inspect", "nowhere.su2"], 2, names=["nowhere.su2"])


def test_mesh_is_a_folder(ws):
    # a folder is a mesh only when it is an OpenFOAM case (docs/openfoam.md): this one is not
    (ws / "folder.su2").mkdir(exist_ok=True)
    assert_hostile(ws, ["inspect", "folder.su2"], 2, "folder without an OpenFOAM mesh", names=["folder.su2"])


def test_mesh_unknown_extension(ws):
    shutil.copyfile(ws / "vwing.su2", ws / "vwing.xyzmesh")
    assert_hostile(ws, ["inspect", "vwing.xyzmesh"], 2, names=["vwing.xyzmesh"])


def test_mesh_empty(ws):
    (ws / "empty.su2").write_text("")
    assert_hostile(ws, ["inspect", "empty.su2"], 2, "empty", names=["empty.su2"])


def test_mesh_binary_garbage(ws):
    (ws / "garbage.su2").write_bytes(bytes(range(256)) * 40)
    assert_hostile(ws, ["inspect", "garbage.su2"], 2, names=["garbage.su2"])


def test_mesh_truncated_mid_element(ws):
    lines = mesh_lines(ws)
    cut = lines[:800] + [lines[800][: len(lines[800]) // 2]]
    name = bad_mesh(ws, "truncated.su2", cut)
    assert_hostile(ws, ["inspect", name], 2, names=["truncated.su2"])


def test_mesh_truncated_in_points_deform(ws):
    lines = mesh_lines(ws)
    i = _find(lines, "NPOIN")
    name = bad_mesh(ws, "trunc_pts.su2", lines[: i + 500])
    design = edit_design(ws, "trunc_pts.yaml", lambda d: d.__setitem__("mesh", name))
    assert_hostile(ws, ["deform", design], 2, names=["trunc_pts.su2"])


def test_mesh_npoin_too_large(ws):
    lines = mesh_lines(ws)
    i = _find(lines, "NPOIN")
    n = int(lines[i].split("=")[1])
    lines[i] = f"NPOIN= {n + 7}\n"
    name = bad_mesh(ws, "npoin_big.su2", lines)
    assert_hostile(ws, ["inspect", name], 2, names=["npoin_big.su2"])


def test_mesh_npoin_too_small(ws):
    lines = mesh_lines(ws)
    i = _find(lines, "NPOIN")
    n = int(lines[i].split("=")[1])
    lines[i] = f"NPOIN= {n - 7}\n"
    name = bad_mesh(ws, "npoin_small.su2", lines)
    assert_hostile(ws, ["inspect", name], 2, names=["npoin_small.su2"])


def test_mesh_nelem_wrong(ws):
    lines = mesh_lines(ws)
    i = _find(lines, "NELEM")
    lines[i] = "NELEM= 1700\n"
    name = bad_mesh(ws, "nelem_big.su2", lines)
    assert_hostile(ws, ["inspect", name], 2, names=["nelem_big.su2"])


def test_mesh_non_numeric_coordinate(ws):
    lines = mesh_lines(ws)
    i = _find(lines, "NPOIN") + 10
    parts = lines[i].split()
    parts[1] = "0.5x"
    lines[i] = "\t".join(parts) + "\n"
    name = bad_mesh(ws, "nonnumeric.su2", lines)
    line = assert_hostile(ws, ["inspect", name], 2, names=["nonnumeric.su2"])
    assert f":{i + 1}" in line, line      # the line of the bad coordinate


def test_mesh_nan_coordinate(ws):
    lines = mesh_lines(ws)
    i = _find(lines, "NPOIN") + 10
    parts = lines[i].split()
    parts[1] = "nan"
    lines[i] = "\t".join(parts) + "\n"
    name = bad_mesh(ws, "nancoord.su2", lines)
    assert_hostile(ws, ["inspect", name], 2, names=["nancoord.su2"])


def test_mesh_nmark_too_small(ws):
    """Found here: NMARK= 2 with four markers in the file silently dropped two markers."""
    lines = mesh_lines(ws)
    i = _find(lines, "NMARK")
    lines[i] = "NMARK= 2\n"
    name = bad_mesh(ws, "nmark_small.su2", lines)
    line = assert_hostile(ws, ["inspect", name], 2, "symmetry", "NMARK", names=["nmark_small.su2:"])
    assert f":{_find(lines, 'MARKER_TAG= symmetry') + 1}:" in line


def test_mesh_last_marker_elems_too_small(ws):
    """Found here: rows beyond the last MARKER_ELEMS= count were silently dropped."""
    lines = mesh_lines(ws)
    i = _find(lines, "MARKER_TAG= side") + 1
    lines[i] = "MARKER_ELEMS= 300\n"
    name = bad_mesh(ws, "melems_small.su2", lines)
    assert_hostile(ws, ["inspect", name], 2, "MARKER_ELEMS", names=["melems_small.su2:"])


def test_mesh_npoin_absurd(ws):
    lines = mesh_lines(ws)
    lines[_find(lines, "NPOIN")] = "NPOIN= 999999999999\n"
    name = bad_mesh(ws, "npoin_absurd.su2", lines)
    assert_hostile(ws, ["inspect", name], 2, "NPOIN", names=["npoin_absurd.su2:"])


def test_mesh_duplicate_marker(ws):
    lines = mesh_lines(ws)
    i = _find(lines, "MARKER_TAG= farfield")
    lines[i] = "MARKER_TAG= wing\n"
    name = bad_mesh(ws, "dupmarker.su2", lines)
    assert_hostile(ws, ["inspect", name], 2, "wing", names=["dupmarker.su2"])


def test_mesh_element_missing_point(ws):
    lines = mesh_lines(ws)
    parts = lines[5].split()
    parts[3] = "99999"
    lines[5] = "\t".join(parts) + "\n"
    name = bad_mesh(ws, "badelem.su2", lines)
    assert_hostile(ws, ["inspect", name], 2, "99999", names=["badelem.su2"])


def test_mesh_marker_element_missing_point(ws):
    lines = mesh_lines(ws)
    i = _find(lines, "MARKER_ELEMS= 200") + 3
    parts = lines[i].split()
    parts[2] = "123456"
    lines[i] = "\t".join(parts) + "\n"
    name = bad_mesh(ws, "badmarker.su2", lines)
    assert_hostile(ws, ["inspect", name], 2, "123456", names=["badmarker.su2"])


def test_mesh_unknown_element_type(ws):
    lines = mesh_lines(ws)
    lines[5] = "77" + lines[5][2:]
    name = bad_mesh(ws, "badtype.su2", lines)
    assert_hostile(ws, ["inspect", name], 2, "77", names=["badtype.su2"])


@pytest.fixture(scope="module")
def other_formats(ws):
    """The wing as CGNS, VTU and legacy VTK (written once, then damaged copies per case)."""
    from ffdcli.io.formats import read_mesh, write_mesh

    mesh = read_mesh(ws / "vwing.su2")
    for ext in ("cgns", "vtu", "vtk"):
        write_mesh(mesh, ws / f"vwing_fmt.{ext}")
    return ws


@pytest.mark.parametrize("ext", ["cgns", "vtu", "vtk"])
@pytest.mark.parametrize("damage", ["truncated", "garbage", "empty"])
def test_other_format_damaged(other_formats, ext, damage):
    ws = other_formats
    data = (ws / f"vwing_fmt.{ext}").read_bytes()
    bad = {"truncated": data[: len(data) // 2], "garbage": b"not a mesh at all\n" * 64, "empty": b""}[damage]
    name = f"{damage}.{ext}"
    (ws / name).write_bytes(bad)
    assert_hostile(ws, ["inspect", name], 2, names=[name])


@pytest.mark.parametrize("damage", ["cell_point_missing", "non_numeric", "npoints_wrong"])
def test_legacy_vtk_damaged(other_formats, damage):
    ws = other_formats
    lines = (ws / "vwing_fmt.vtk").read_text().split("\n")
    cells = next(i for i, ln in enumerate(lines) if ln.startswith("CELLS"))
    pts = next(i for i, ln in enumerate(lines) if ln.startswith("POINTS"))
    if damage == "cell_point_missing":
        first = cells + 1 + (1 if lines[cells + 1].startswith("OFFSETS") else 0)
        lines[first + 1] = "99999"           # the first point id of the first cell
    elif damage == "non_numeric":
        lines[pts + 1] = "abc " + lines[pts + 1]
    else:
        lines[pts] = lines[pts].replace(lines[pts].split()[1], "100")
    name = f"vtk_{damage}.vtk"
    (ws / name).write_text("\n".join(lines))
    assert_hostile(ws, ["inspect", name], 2, names=[name])


def test_check_damaged_mesh(ws):
    lines = mesh_lines(ws)
    name = bad_mesh(ws, "check_trunc.su2", lines[: len(lines) // 3])
    assert_hostile(ws, ["check", name], 2, names=["check_trunc.su2"])


def test_fit_output_over_design(ws):
    name = _airfoil_design(ws, "airfoil_fit_over.yaml", {"shape": {"upper": [0] * 6, "lower": [0] * 6}})
    assert_hostile(ws, ["fit", name, "--target", str(SAMPLES / "s1223.dat"), "-o", name], 2, "overwrite",
                   names=[name])


def test_surface_marker_without_elements(ws):
    lines = mesh_lines(ws)
    i = _find(lines, "MARKER_TAG= wing")
    n = int(lines[i + 1].split("=")[1])
    name = bad_mesh(ws, "nowing.su2", lines[: i + 1] + ["MARKER_ELEMS= 0\n"] + lines[i + 2 + n:])
    assert_hostile(ws, ["box", name, "--surface", "wing"], 2, "no points", names=["nowing.su2"])


def test_degenerate_mesh_all_points_equal(ws):
    from ffdcli.io.formats import read_mesh, write_mesh

    mesh = read_mesh(ws / "vwing.su2")
    write_mesh(mesh.with_points(np.zeros_like(mesh.points)), ws / "collapsed.su2")
    assert_hostile(ws, ["box", "collapsed.su2", "--surface", "wing"], 2, "extent", names=["collapsed.su2"])


@pytest.mark.parametrize("text", ["NACA\n1 0\n0.5 nan\n0 0\n0.5 -0.1\n1 0\n", "NACA\n1 0\n0 0\n",
                                  "NACA\n" + "0.5 0.0\n" * 20],
                         ids=["nan", "two_points", "all_equal"])
def test_fit_target_bad_airfoil(ws, text):
    (ws / "bad_airfoil.dat").write_text(text)
    name = _airfoil_design(ws, "airfoil_fit2.yaml", {"shape": {"upper": [0] * 6, "lower": [0] * 6}})
    assert_hostile(ws, ["fit", name, "--target", "bad_airfoil.dat", "-o", "fitted.yaml"], 2,
                   names=["bad_airfoil.dat"])


def test_marker_does_not_exist_design(ws):
    name = edit_design(ws, "no_marker.yaml", lambda d: d.__setitem__("surface", "fuselage"))
    assert_hostile(ws, ["deform", name], 2, "fuselage", names=["vwing.su2"])


def test_marker_does_not_exist_box(ws):
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "fuselage"], 2, "fuselage", names=["vwing.su2"])


def test_box_too_few_points(ws):
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "wing", "--points", "1,8,2"], 2)


def test_box_points_not_numbers(ws):
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "wing", "--points", "6,x,2"], 2)


# ----------------------------------------------------------------------------------------------
# Outputs
# ----------------------------------------------------------------------------------------------

def test_output_in_missing_folder(ws):
    assert_hostile(ws, ["deform", "good.yaml", "-o", "no/such/dir/out.su2"], 2, "does not exist",
                   names=["out.su2"])
    assert not (ws / "no").exists()


def test_output_design_in_missing_folder(ws):
    name = edit_design(ws, "out_missing.yaml", lambda d: None)
    data = yaml.safe_load((ws / name).read_text())
    data["output"]["mesh"] = "missing_dir/x.su2"
    (ws / name).write_text(yaml.safe_dump(data))
    assert_hostile(ws, ["deform", name], 2, names=["x.su2"])


def test_output_in_read_only_folder(ws):
    if os.geteuid() == 0:
        pytest.skip("root can write into a read-only folder")
    ro = ws / "readonly"
    ro.mkdir(exist_ok=True)
    ro.chmod(0o555)
    try:
        assert_hostile(ws, ["deform", "good.yaml", "-o", "readonly/out.su2"], 2, "not writable",
                       names=["out.su2"])
    finally:
        ro.chmod(0o755)


def test_output_equals_input(ws):
    assert_hostile(ws, ["deform", "good.yaml", "-o", "vwing.su2"], 2, "input", names=["vwing.su2"])


def test_output_equals_input_other_spelling(ws):
    assert_hostile(ws, ["deform", "good.yaml", "-o", "./sub/../vwing.su2"], 2, "input")


def test_output_in_design_equals_input(ws):
    name = edit_design(ws, "out_is_in.yaml", lambda d: None)
    data = yaml.safe_load((ws / name).read_text())
    data["output"]["mesh"] = "vwing.su2"
    (ws / name).write_text(yaml.safe_dump(data))
    assert_hostile(ws, ["deform", name], 2, names=["out_is_in.yaml"])


def test_lattice_output_equals_input(ws):
    assert_hostile(ws, ["deform", "good.yaml", "--lattice", "vwing.su2"], 2, "input")


@pytest.mark.parametrize("args", [["deform", "good.yaml", "--lattice", "good.yaml"],
                                  ["deform", "good.yaml", "-o", "same.su2", "--lattice", "same.su2"],
                                  ["plot", "good.yaml", "-o", "good.yaml"]],
                         ids=["lattice_over_design", "lattice_over_mesh_output", "plot_over_design"])
def test_output_over_the_design_file(ws, args):
    """Found here: ``--lattice DESIGN.yaml`` replaced the design file with the lattice VTK."""
    assert_hostile(ws, args, 2, "overwrite")


def test_output_symlink_to_input(ws):
    link = ws / "link.su2"
    if not link.exists():
        link.symlink_to("vwing.su2")
    assert_hostile(ws, ["deform", "good.yaml", "-o", "link.su2"], 2, "input mesh", names=["link.su2"])
    assert link.is_symlink()


def test_output_is_a_folder(ws):
    (ws / "afolder.su2").mkdir(exist_ok=True)
    assert_hostile(ws, ["deform", "good.yaml", "-o", "afolder.su2"], 2, "directory", names=["afolder.su2"],
                   usage=True)


def test_output_unknown_format(ws):
    assert_hostile(ws, ["deform", "good.yaml", "-o", "out.unknownfmt"], 2, names=["out.unknownfmt"])


def test_plot_output_missing_folder(ws):
    assert_hostile(ws, ["plot", "good.yaml", "-o", "nodir/pic.png"], 2, names=["pic.png"])


def test_grad_output_missing_folder(ws):
    sens = _sens_csv(ws, "sens_ok.csv", ids=[0, 1, 2])
    assert_hostile(ws, ["grad", "good.yaml", "--sens", sens, "-o", "nodir/g.json"], 2, names=["g.json"])


@pytest.mark.parametrize("target", ["vwing.su2", "good.yaml", "sens_ok.csv"])
def test_grad_output_over_an_input(ws, target):
    """Found here: ``ffd grad -o MESH`` replaced the input mesh with the JSON gradient."""
    sens = _sens_csv(ws, "sens_ok.csv", ids=[0, 1, 2])
    assert_hostile(ws, ["grad", "good.yaml", "--sens", sens, "-o", target], 2, "overwrite", names=[target])


@pytest.mark.parametrize("target", ["vwing.su2", "good.yaml"])
def test_jacobian_output_over_an_input(ws, target):
    assert_hostile(ws, ["jacobian", "good.yaml", "-o", target], 2, "overwrite", names=[target])


def test_box_lattice_file_missing(ws):
    """Found here: ``ffd box --from MISSING`` crashed with FileNotFoundError (exit 1)."""
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "wing", "--from", "nofile.xyz"], 2,
                   names=["nofile.xyz"])


def test_box_lattice_file_garbage(ws):
    (ws / "bad_lattice.xyz").write_text("1\n2 2 2\n0 0 0\n")
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "wing", "--from", "bad_lattice.xyz"], 2,
                   names=["bad_lattice.xyz"])


def test_box_lattice_output_is_input(ws):
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "wing", "--lattice", "vwing.su2"], 2, "input",
                   names=["vwing.su2"])


def test_plot_output_is_input(ws):
    assert_hostile(ws, ["plot", "good.yaml", "-o", "vwing.su2"], 2, "input", names=["vwing.su2"])


# ----------------------------------------------------------------------------------------------
# Sensitivity files
# ----------------------------------------------------------------------------------------------

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


def test_fit_on_3d_design(ws):
    assert_hostile(ws, ["fit", "good.yaml", "--target", str(SAMPLES / "s1223.dat")], 2, names=["good.yaml"])


def test_fit_target_garbage(ws):
    (ws / "junk.dat").write_text("this is not\nan airfoil\n")
    name = _airfoil_design(ws, "airfoil_fit.yaml", {"shape": {"upper": [0] * 6, "lower": [0] * 6}})
    assert_hostile(ws, ["fit", name, "--target", "junk.dat"], 2, names=["junk.dat"])


# ----------------------------------------------------------------------------------------------
# The quality gate
# ----------------------------------------------------------------------------------------------

def test_absurd_twist_refused_by_quality_gate(ws):
    shutil.copyfile(SAMPLES / "rect_wing.su2", ws / "rect_wing.su2")
    data = yaml.safe_load((REPO / "configs" / "rect_twist_linear.yaml").read_text())
    data["mesh"] = "rect_wing.su2"
    data["changes"] = [{"twist": {"tip": 170}}]
    data["output"] = {"mesh": "out_absurd.su2", "lattice": "out_absurd_lattice.vtk"}
    (ws / "absurd.yaml").write_text(yaml.safe_dump(data))
    assert_hostile(ws, ["deform", "absurd.yaml"], 3, "quality", names=["absurd.yaml"])
    assert not (ws / "out_absurd.su2").exists()


# ----------------------------------------------------------------------------------------------
# The cache: a foreign, corrupt or other-version cache file is rebuilt, never used
# ----------------------------------------------------------------------------------------------

def _good_cache(ws: Path) -> Path:
    caches = sorted(ws.glob("vwing.su2.*.ffdcache.npz"))
    assert len(caches) == 1, caches
    return caches[0]


def _good_run_reuses_or_rebuilds(ws: Path, expect_from_cache: bool):
    """The good design runs, writes the reference output bit for bit, and leaves a valid cache."""
    out = ws / "cache_check.su2"
    out.unlink(missing_ok=True)
    proc = ffd("deform", "good.yaml", "-o", out.name, "--json", cwd=ws)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["from_cache"] is expect_from_cache
    assert file_hash(out) == file_hash(ws / "ref_out.su2")
    out.unlink()


def test_cache_from_another_mesh(ws, tmp_path):
    other = write_volume_wing(tmp_path, name="vwing.su2", semi_span=2.5, taper=0.7)
    write_design(tmp_path, other, GOOD, name="good.yaml")
    proc = ffd("deform", "good.yaml", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    foreign = next(tmp_path.glob("vwing.su2.*.ffdcache.npz"))
    cache = _good_cache(ws)
    saved = cache.read_bytes()
    mesh_hash = file_hash(ws / "vwing.su2")
    try:
        assert file_hash(foreign) != file_hash(cache)
        shutil.copyfile(foreign, cache)        # same file name, another mesh's content
        _good_run_reuses_or_rebuilds(ws, expect_from_cache=False)
        _good_run_reuses_or_rebuilds(ws, expect_from_cache=True)
        assert file_hash(ws / "vwing.su2") == mesh_hash
    finally:
        cache.write_bytes(saved)


def test_cache_corrupt(ws):
    cache = _good_cache(ws)
    saved = cache.read_bytes()
    try:
        cache.write_bytes(b"PK\x03\x04" + os.urandom(2000))
        _good_run_reuses_or_rebuilds(ws, expect_from_cache=False)
        cache.write_bytes(saved[: len(saved) // 2])      # truncated
        _good_run_reuses_or_rebuilds(ws, expect_from_cache=False)
        _good_run_reuses_or_rebuilds(ws, expect_from_cache=True)
    finally:
        cache.write_bytes(saved)


def _rewrite_header(cache: Path, **changes):
    with np.load(cache, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(bytes(arrays["header"]).decode())
    header.update(changes)
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    with open(cache, "wb") as fh:
        np.savez(fh, **arrays)


@pytest.mark.parametrize("field,value", [("version", "0.0.0-other"), ("format", 999), ("key", "0" * 64)])
def test_cache_other_version(ws, field, value):
    cache = _good_cache(ws)
    saved = cache.read_bytes()
    try:
        _rewrite_header(cache, **{field: value})
        _good_run_reuses_or_rebuilds(ws, expect_from_cache=False)
        with np.load(cache) as z:          # replaced by a valid cache of this version
            from ffdcli import __version__

            assert json.loads(bytes(z["header"]).decode())["version"] == __version__
    finally:
        cache.write_bytes(saved)


@pytest.mark.parametrize("array,damage", [
    ("params", lambda v: v * 7.0),                  # parameters outside [0, 1]
    ("control_points", lambda v: v * np.nan),       # found here: used, then "contain NaN" (no file)
    ("le_points", lambda v: v * np.nan),            # found here: used silently
    ("control_points", lambda v: v[:, :3]),         # found here: used, then a lattice error (no file)
], ids=["params_out_of_range", "nan_control_points", "nan_le_points", "lattice_shape"])
def test_cache_arrays_tampered(ws, array, damage):
    """A cache whose header is right but whose arrays are damaged is rebuilt, never used."""
    cache = _good_cache(ws)
    saved = cache.read_bytes()
    try:
        with np.load(cache, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        arrays[array] = damage(arrays[array])
        with open(cache, "wb") as fh:
            np.savez(fh, **arrays)
        _good_run_reuses_or_rebuilds(ws, expect_from_cache=False)
        _good_run_reuses_or_rebuilds(ws, expect_from_cache=True)
    finally:
        cache.write_bytes(saved)


# ----------------------------------------------------------------------------------------------
# A few cases through a real subprocess (the console script path, its stderr, its exit status)
# ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("args,code", [
    (["deform", "empty.yaml"], 2),
    (["deform", "good.yaml", "--set", "changes.0.twist.tipp=12"], 2),
    (["inspect", "badelem.su2"], 2),
    (["deform", "good.yaml", "-o", "vwing.su2"], 2),
], ids=["empty_design", "set_unknown", "element_missing_point", "output_is_input"])
def test_subprocess_smoke(ws, args, code):
    for name in ("empty.yaml", "badelem.su2"):
        if not (ws / name).exists():
            pytest.skip(f"{name} is made by an earlier case")
    assert_hostile(ws, args, code, subprocess_run=True)


# ----------------------------------------------------------------------------------------------
# Last: nothing above poisoned the cache or touched the mesh
# ----------------------------------------------------------------------------------------------

def test_zz_cache_not_poisoned(ws):
    assert file_hash(ws / "vwing.su2") == (ws / "vwing.su2.sha256").read_text()
    assert not list(ws.rglob("*.part*"))
    _good_run_reuses_or_rebuilds(ws, expect_from_cache=True)


def test_sensitivity_missing_surface_nodes_is_an_error(tmp_path):
    """A surface sensitivity file that leaves out some wing nodes is an error, not a partial gradient."""
    import numpy as np
    from conftest import assert_clean_failure, run_ffd
    from wingcase import write_design, write_surface_wing

    from ffdcli.api import DesignModel

    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"span": 1.1}])
    model = DesignModel.from_file(design)
    X = model.surface_points()
    rows = np.c_[X, np.ones_like(X)][:-3]
    np.savetxt(tmp_path / "part.dat", rows, fmt="%.17g")
    assert_clean_failure(run_ffd("grad", str(design), "--sens", str(tmp_path / "part.dat")), 2, "part.dat",
                         "no row for 3")


def test_lattice_and_picture_extensions(tmp_path):
    from conftest import assert_clean_failure, run_ffd
    from wingcase import write_design, write_surface_wing

    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"span": 1.1}])
    assert_clean_failure(run_ffd("deform", str(design), "--lattice", str(tmp_path / "l.su2")), 2, "l.su2", ".vtk")
    assert not (tmp_path / "l.su2").exists()
    assert_clean_failure(run_ffd("plot", str(design), "-o", str(tmp_path / "p.txt")), 2, "p.txt", ".png")
    bad = write_design(tmp_path, mesh, [{"span": 1.1}], name="t.yaml", volume={"method": "idw", "threshold": 7})
    assert_clean_failure(run_ffd("deform", str(bad)), 2, "volume.threshold")
