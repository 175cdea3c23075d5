"""Outputs are refused before the work when they cannot be written as asked: a missing or read-only
folder, an output over an input (any spelling, symlinks), a folder, a FIFO or device, an unknown
extension, a name too long; ``-o`` names the whole run (lattice and picture beside it).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
import yaml
from conftest import REPO, SAMPLES, assert_clean_failure, file_hash, run_ffd
from hostile import (
    GOOD,
    assert_hostile,
    edit_design,
    ffd,
    no_parts,
)
from wingcase import write_design, write_volume_wing

pytest_plugins = ["hostile"]        # the workspaces: fixtures ws, ws2


# 2D-only rules on the 2D config: span, sweep and dihedral do not exist; twist/chord are one number.
def _airfoil_design(ws: Path, name: str, change) -> str:
    data = yaml.safe_load((REPO / "configs" / "naca0012_s1223.yaml").read_text())
    data["mesh"] = str(SAMPLES / "naca0012_2d.su2")
    data["changes"] = [change]
    data["output"] = {"mesh": f"out_{Path(name).stem}.su2", "lattice": f"out_{Path(name).stem}_lattice.vtk"}
    (ws / name).write_text(yaml.safe_dump(data, sort_keys=False))
    return name


def test_fit_output_over_design(ws):
    name = _airfoil_design(ws, "airfoil_fit_over.yaml", {"shape": {"upper": [0] * 6, "lower": [0] * 6}})
    assert_hostile(ws, ["fit", name, "--target", str(SAMPLES / "s1223.dat"), "-o", name], 2, "overwrite",
                   names=[name])


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
    assert_hostile(ws, ["deform", "good.yaml", "-o", "afolder.su2"], 2, "is a folder", names=["afolder.su2"])


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


def test_box_lattice_output_is_input(ws):
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "wing", "--lattice", "vwing.su2"], 2, "input",
                   names=["vwing.su2"])


def test_plot_output_is_input(ws):
    assert_hostile(ws, ["plot", "good.yaml", "-o", "vwing.su2"], 2, "input", names=["vwing.su2"])


def _sens_csv(ws: Path, name: str, ids) -> str:
    rows = ['"PointID","x","y","z","Sensitivity_x","Sensitivity_y","Sensitivity_z"']
    rows += [f"{i},0,0,0,1,0,0" for i in ids]
    (ws / name).write_text("\n".join(rows) + "\n")
    return name


def test_lattice_and_picture_extensions(tmp_path):
    from wingcase import write_design, write_surface_wing

    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"span": 1.1}])
    assert_clean_failure(run_ffd("deform", str(design), "--lattice", str(tmp_path / "l.su2")), 2, "l.su2", ".vtk")
    assert not (tmp_path / "l.su2").exists()
    assert_clean_failure(run_ffd("plot", str(design), "-o", str(tmp_path / "p.txt")), 2, "p.txt", ".png")
    bad = write_design(tmp_path, mesh, [{"span": 1.1}], name="t.yaml", volume={"method": "idw", "threshold": 7})
    assert_clean_failure(run_ffd("deform", str(bad)), 2, "volume.threshold")


def test_output_name_too_long_is_refused_before_the_work(ws2):
    name = "n" * 300 + ".su2"
    line = assert_hostile(ws2, ["deform", "good.yaml", "-o", name], 2, "too long")
    assert "bug" not in line


def test_long_name_that_fits_is_written(ws2):
    """A name near the file system's limit: the temporary name is shortened, the output is written."""
    name = "L" * 240 + ".su2"
    proc = ffd("deform", "good.yaml", "-o", name, "--lattice", "long_lattice.vtk", "-q", cwd=ws2)
    assert proc.returncode == 0, proc.stderr
    assert (ws2 / name).is_file() and no_parts(ws2) == []
    (ws2 / name).unlink()
    (ws2 / "long_lattice.vtk").unlink()


def test_output_is_a_fifo(ws2):
    fifo = ws2 / "fifo_out.su2"
    os.mkfifo(fifo)
    try:
        assert_hostile(ws2, ["deform", "good.yaml", "-o", fifo.name], 2, "FIFO", names=["fifo_out.su2"])
        assert fifo.is_fifo()
    finally:
        fifo.unlink()


def test_output_is_a_character_device(ws2):
    link = ws2 / "devnull_lattice.vtk"
    link.symlink_to("/dev/null")
    try:
        assert_hostile(ws2, ["deform", "good.yaml", "--lattice", link.name], 2, "character device")
        assert Path("/dev/null").is_char_device()
    finally:
        link.unlink()


def test_output_is_a_symlink_loop(ws2):
    loop = ws2 / "loop_out.su2"
    loop.symlink_to(loop.name)
    try:
        assert_hostile(ws2, ["deform", "good.yaml", "-o", loop.name], 2, "symlink loop")
    finally:
        loop.unlink()


def test_unsupported_output_extension_refused_before_reading_the_mesh(ws2):
    """Found: refused after 12 s of reading, deforming and checking a 280 MB mesh. Here the mesh is
    garbage: a check made before reading it names the extension, not the mesh."""
    (ws2 / "garbage.su2").write_bytes(b"NDIME= 3\nthis is not a mesh\n" * 10)
    write_design(ws2, ws2 / "garbage.su2", GOOD, name="garbage.yaml")
    assert_hostile(ws2, ["deform", "garbage.yaml", "-o", "out.xyz"], 2, "unsupported mesh extension", names=["out.xyz"])
    assert_hostile(ws2, ["deform", "garbage.yaml", "--lattice", "l.su2"], 2, ".vtk", names=["l.su2"])
    assert_hostile(ws2, ["plot", "garbage.yaml", "-o", "p.jpg"], 2, ".png", names=["p.jpg"])


@pytest.mark.parametrize("args", [["deform", "good.yaml", "-o", ""], ["deform", "good.yaml", "--lattice", ""],
                                  ["plot", "good.yaml", "-o", ""], ["jacobian", "good.yaml", "-o", ""],
                                  ["box", "vwing.su2", "--surface", "wing", "--lattice", ""]],
                         ids=["deform", "lattice", "plot", "jacobian", "box"])
def test_empty_output_name(ws2, args):
    """Found: ``-o ''`` was ignored silently (the default output was written)."""
    assert_hostile(ws2, args, 2, "empty")


def test_output_name_carries_lattice_and_picture(ws2):
    (ws2 / "loop").mkdir(exist_ok=True)
    for t in (3, 6):
        proc = ffd("deform", "good.yaml", "--set", f"changes.0.twist.tip={t}", "-o", f"loop/t{t}.su2", "--plot",
                   "--json", cwd=ws2)
        assert proc.returncode == 0, proc.stderr
        s = json.loads(proc.stdout)
        assert ws2 / s["lattice_file"] == ws2 / "loop" / f"t{t}_lattice.vtk"
        assert ws2 / s["plot"] == ws2 / "loop" / f"t{t}.png"
    names = sorted(p.name for p in (ws2 / "loop").iterdir())
    views = [n for n in names if n.endswith("_3d.png")]      # the 3D view: only where pyvista renders
    assert views in ([], ["t3_3d.png", "t6_3d.png"])
    assert [n for n in names if n not in views] == [
        "t3.png", "t3.su2", "t3_lattice.vtk", "t6.png", "t6.su2", "t6_lattice.vtk"]
    assert file_hash(ws2 / "loop" / "t3_lattice.vtk") != file_hash(ws2 / "loop" / "t6_lattice.vtk")
    proc = ffd("deform", "good.yaml", "-o", "loop/t9.su2", "--lattice", "loop/given.vtk", "-q", cwd=ws2)
    assert proc.returncode == 0, proc.stderr
    assert (ws2 / "loop" / "given.vtk").is_file() and not (ws2 / "loop" / "t9_lattice.vtk").exists()


def test_default_outputs_go_to_out_beside_the_design(tmp_path):
    mesh = write_volume_wing(tmp_path)
    (tmp_path / "d.yaml").write_text(f"mesh: {mesh.name}\nsurface: wing\nbox: {{points: [6, 8, 2]}}\n"
                                     "changes: [{twist: {tip: 2}}]\n")
    proc = ffd("deform", "d.yaml", "--plot", "-q", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    names = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert [n for n in names if n != "d_3d.png"] == ["d.png", "d.su2", "d_lattice.vtk"]   # + 3D view with pyvista



def test_zz_the_workspace_is_as_it_was(ws):
    """Last: no case touched the mesh or left a .part file."""
    assert file_hash(ws / "vwing.su2") == (ws / "vwing.su2.sha256").read_text()
    assert not list(ws.rglob("*.part*"))
