"""Paths on the command line: ffd's own checks decide (click's refused a folder before them, so an
OpenFOAM case could not be written a second time with ``-o``), and a design file that a command writes
(``ffd init``, ``ffd fit``) is never replaced without ``--force``."""

from __future__ import annotations

import pytest
from conftest import SAMPLES, run_ffd
from hostile import ffd_inproc
from wingcase import write_design, write_volume_wing

from ffdcli.io.formats import read_mesh
from ffdcli.io.formats.openfoam_case import polymesh_of, write_case
from ffdcli.testing.wings import extruded_wing_mesh


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    d = tmp_path_factory.mktemp("paths")
    mesh = write_volume_wing(d)
    write_design(d, mesh, [{"twist": {"tip": 3}}], name="good.yaml")
    (d / "naca.su2").write_bytes((SAMPLES / "naca0012_2d.su2").read_bytes())
    (d / "naca.yaml").write_text("mesh: naca.su2\nsurface: airfoil\nbox: {points: [8, 5]}\nchanges: []\n")
    (d / "s1223.dat").write_bytes((SAMPLES / "s1223.dat").read_bytes())
    (d / "afolder").mkdir()
    return d


#: (command and its other arguments, the position where the folder goes)
FOLDER_AS_FILE = [
    (["deform", "{}"], "expected a design file"),
    (["deform", "good.yaml", "--lattice", "{}"], ".vtk"),
    (["deform", "good.yaml", "--surface-file", "{}"], "is a folder"),
    (["plot", "{}"], "expected a design file"),
    (["plot", "good.yaml", "-o", "{}"], ".png"),
    (["plot", "naca.yaml", "--target", "{}"], "expected an airfoil file"),
    (["fit", "{}", "--target", "s1223.dat"], "expected a design file"),
    (["fit", "naca.yaml", "--target", "s1223.dat", "-o", "{}"], ".yaml"),
    (["init", "vwing.su2", "-o", "{}"], ".yaml"),
    (["grad", "{}", "--sens", "x.csv"], "expected a design file"),
    (["grad", "good.yaml", "--sens", "{}"], "expected a sensitivity file"),
    (["jacobian", "{}", "-o", "j.npz"], "expected a design file"),
    (["jacobian", "good.yaml", "-o", "{}"], "is a folder"),
    (["vars", "{}"], "expected a design file"),
    (["constraints", "{}"], "expected a design file"),
    (["constraints", "good.yaml", "--jacobian", "{}"], "is a folder"),
    (["box", "vwing.su2", "--surface", "wing", "--lattice", "{}"], ".vtk"),
    (["box", "vwing.su2", "--surface", "wing", "--export-plot3d", "{}"], "is a folder"),
]


@pytest.mark.parametrize("args, words", FOLDER_AS_FILE, ids=[" ".join(a) for a, _ in FOLDER_AS_FILE])
def test_a_folder_where_a_file_is_expected_is_ffds_one_line(ws, args, words):
    argv = [a.replace("{}", "afolder") for a in args]
    proc = ffd_inproc(*argv, cwd=ws)
    assert proc.returncode == 2, (argv, proc.stderr)
    line = proc.stderr.strip().splitlines()[-1]      # after the compile notice of a first run, if any
    assert line.startswith("ffd: error: afolder") and words in line, line     # ffd's words, the path first
    assert "--help` shows the usage" not in line                               # not click's refusal


def test_openfoam_case_output_can_be_written_again(tmp_path):
    """Found here: ``ffd deform D.yaml -o out/case`` ran once; the second time click refused the folder."""
    mesh = extruded_wing_mesh(n_around=25, n_radial=7, n_span=4)
    poly, patches = polymesh_of(mesh, wall=("wing",))
    write_case(tmp_path / "case", mesh.points, poly, patches)
    (tmp_path / "out").mkdir()
    for k, tip in enumerate((3, -2, 5)):
        (tmp_path / "d.yaml").write_text(f"mesh: case\nsurface: wing\nbox: {{points: [5, 4, 2]}}\n"
                                         f"changes:\n  - twist: {{tip: {tip}}}\n")
        r = run_ffd("deform", "d.yaml", "-o", "out/case", "--lattice", f"out/l{k}.vtk", cwd=tmp_path)
        assert r.returncode == 0, (k, r.stderr)
        assert read_mesh(tmp_path / "out" / "case").n_points == len(mesh.points)


@pytest.mark.parametrize("how", ["default", "-o"])
def test_fit_never_replaces_a_design_file_without_force(ws, how):
    """Found here: ``ffd fit`` replaced an existing ``<design>_fitted.yaml`` (hand edits) silently."""
    out = ws / ("naca_fitted.yaml" if how == "default" else "mine.yaml")
    out.write_text("# my hand edits\n")
    extra = [] if how == "default" else ["-o", out.name]
    proc = ffd_inproc("fit", "naca.yaml", "--target", "s1223.dat", *extra, cwd=ws)
    assert proc.returncode == 2 and "--force" in proc.stderr and out.name in proc.stderr, proc.stderr
    assert out.read_text() == "# my hand edits\n"
    proc = ffd_inproc("fit", "naca.yaml", "--target", "s1223.dat", *extra, "--force", "--json", cwd=ws)
    assert proc.returncode == 0, proc.stderr
    assert out.read_text().startswith("# fitted by ffd fit")


@pytest.mark.parametrize("what", ["design file", "empty file", "symlink"])
def test_init_and_fit_refuse_any_existing_file_alike(ws, tmp_path, what):
    """One rule for both commands that write a design file: whatever is there, --force or another name."""
    target = tmp_path / "x.yaml"
    if what == "design file":
        target.write_text("mesh: a.su2\n")
    elif what == "empty file":
        target.write_text("")
    else:
        (tmp_path / "real.yaml").write_text("mesh: a.su2\n")
        target.symlink_to(tmp_path / "real.yaml")
    before = target.read_text()
    for argv in (["init", "vwing.su2", "--surface", "wing", "-o", target],
                 ["fit", "naca.yaml", "--target", "s1223.dat", "-o", target]):
        proc = ffd_inproc(*argv, cwd=ws)
        assert proc.returncode == 2 and "pass --force to replace it" in proc.stderr, proc.stderr
        assert target.read_text() == before


def test_fit_of_a_3d_design_says_2d_first(ws):
    """Found here: ``ffd fit`` on a 3-D design first asked to remove the twist, then said it works on 2-D."""
    proc = ffd_inproc("fit", "good.yaml", "--target", "s1223.dat", "-o", "f3.yaml", cwd=ws)
    assert proc.returncode == 2 and "2D" in proc.stderr and "twist" not in proc.stderr, proc.stderr
