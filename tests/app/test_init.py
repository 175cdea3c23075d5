"""``ffd init``: the starter design file (library text, CLI, and the round trip through deform)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import yaml
from conftest import SAMPLES, assert_clean_failure, file_hash, run_ffd

from ffdcli.app.starter import _flow, starter_design, volume_defaults
from ffdcli.design import changes_from_spec, load_design
from ffdcli.io.formats import read_mesh, write_mesh
from ffdcli.testing.wings import Planform, extruded_wing_mesh, surface_mesh
from ffdcli.volume.warp import WarpSettings


def _commented_changes(text: str) -> list[str]:
    """The commented change items of a starter text, each as the YAML of a one-item list."""
    out, inside = [], False
    for line in text.splitlines():
        if line.startswith("changes:"):
            inside = True
            continue
        if inside and not line.startswith("  "):
            break
        if inside and line.startswith("  # - "):
            out.append(line[4:].split("  #")[0])
    return out


@pytest.mark.parametrize("planform, sections", [
    (dict(semi_span=3.0, root_chord=1.0, sections="xy"), "xy"),                     # span z
    (dict(semi_span=4.0, root_chord=1.2, taper=0.5, le_sweep_deg=30, sections="xz"), "xz"),  # span y
    (dict(semi_span=3.0, root_chord=0.8, sections="yz", root_side="max"), "yz"),    # span x, root at max
])
def test_starter_text_detects_axes_and_every_change_uncomments(tmp_path, planform, sections):
    pf = dict(planform)
    root_side = pf.pop("root_side", "min")
    mesh = surface_mesh(Planform(**pf), n_chord=25, n_span=9)
    if root_side == "max":                   # a left wing: the span runs towards -x
        span_axis = 3 - "xyz".index(sections[0]) - "xyz".index(sections[1])
        mesh.points[:, span_axis] *= -1
    path = tmp_path / "w.su2"
    write_mesh(mesh, path)
    text = starter_design(path, design_path=tmp_path / "w.yaml")
    data = yaml.safe_load(text)
    assert data["box"]["sections"] == sections
    assert data["box"]["root"] == root_side
    assert data["surface"] == "wing"
    assert data["mesh"] == "w.su2"
    assert not data.get("changes")
    # every change kind is there, commented out, and each line is a valid change once uncommented
    items = _commented_changes(text)
    kinds = {next(iter(yaml.safe_load(t)[0])) for t in items}
    assert kinds == {"twist", "span", "sweep", "dihedral", "chord", "shape"}
    n, m, l = data["box"]["points"]
    for item in items:
        (tmp_path / "one.yaml").write_text(text.replace("  # " + item, "  " + item, 1))
        design = load_design(tmp_path / "one.yaml")
        assert len(design.changes_spec) == 1, item
        changes_from_spec(design.changes_spec, n, m, l, 3)       # lengths match the lattice


def test_volume_block_is_the_warp_defaults(tmp_path):
    text = starter_design(SAMPLES / "naca0012_2d.su2", design_path=tmp_path / "a.yaml")
    volume = yaml.safe_load(text)["volume"]
    defaults = {f.name: f.default for f in dataclasses.fields(WarpSettings)}
    written = {k for k, v, _ in volume_defaults() if v is not None}
    assert written <= set(volume)
    for key in written - {"threshold"}:
        assert volume[key] == defaults[key], key
    WarpSettings(**{k: v for k, v in volume.items() if k in defaults})   # valid as written


def test_2d_starter_has_only_2d_changes(tmp_path):
    text = starter_design(SAMPLES / "naca0012_2d.su2", design_path=tmp_path / "a.yaml")
    data = yaml.safe_load(text)
    assert len(data["box"]["points"]) == 2
    items = _commented_changes(text)
    kinds = {next(iter(yaml.safe_load(t)[0])) for t in items}
    assert kinds == {"twist", "chord", "shape"}
    n, l = data["box"]["points"]
    for item in items:
        (tmp_path / "one.yaml").write_text(text.replace("  # " + item, "  " + item, 1))
        changes_from_spec(load_design(tmp_path / "one.yaml", check_files=False).changes_spec, n, 1, l, 2)


def test_marker_names_are_quoted_when_yaml_needs_it():
    assert _flow("wing") == "wing"
    assert yaml.safe_load(_flow("1")) == "1"
    assert yaml.safe_load(_flow("wing: upper")) == "wing: upper"
    assert yaml.safe_load(_flow(["a b", "yes"])) == ["a b", "yes"]


def _init_deform_roundtrip(tmp_path, mesh_path, *args):
    proc = run_ffd("init", mesh_path, "-o", tmp_path / "design.yaml", *args)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "out").is_dir()
    proc = run_ffd("deform", tmp_path / "design.yaml", "--json")
    assert proc.returncode == 0, proc.stderr
    out = tmp_path / "out" / f"design{mesh_path.suffix}"
    return out


def test_init_then_deform_unedited_gives_the_input_back_bit_for_bit(tmp_path):
    mesh = extruded_wing_mesh(Planform(semi_span=2.0, root_chord=1.0, taper=0.6, le_sweep_deg=20,
                                       sections="xz"), n_around=41, n_radial=9, n_span=6)
    src = tmp_path / "vwing.su2"
    write_mesh(mesh, src)
    before = file_hash(src)
    out = _init_deform_roundtrip(tmp_path, src, "--surface", "wing")
    assert file_hash(src) == before
    assert out.read_bytes() == src.read_bytes()


def test_init_then_deform_unedited_2d(tmp_path):
    src = SAMPLES / "naca0012_2d.su2"
    out = _init_deform_roundtrip(tmp_path, src)
    np.testing.assert_array_equal(read_mesh(out).points, read_mesh(src).points)
    assert out.read_bytes() == src.read_bytes()


def test_init_cli_refuses_to_overwrite_and_names_bad_markers(tmp_path):
    src = SAMPLES / "naca0012_2d.su2"
    target = tmp_path / "a.yaml"
    assert run_ffd("init", src, "-o", target).returncode == 0
    text = target.read_text()
    assert_clean_failure(run_ffd("init", src, "-o", target), 2, "--force")
    assert target.read_text() == text
    assert run_ffd("init", src, "-o", target, "--force", "-q").returncode == 0
    assert_clean_failure(run_ffd("init", src, "-o", tmp_path / "a.txt"), 2, ".yaml")
    assert_clean_failure(run_ffd("init", src, "-o", target, "--force", "--surface", "nope"), 2, "nope")
    assert target.read_text() == text


def test_init_of_an_extruded_airfoil_says_so_and_puts_the_span_along_the_extrusion(tmp_path):
    from test_inspect import _extruded_airfoil

    p = _extruded_airfoil(tmp_path, merge=True)
    text = starter_design(p, ["wing"], design_path=tmp_path / "e.yaml")
    # both side planes on one marker now slide, each node in its own plane (docs/openfoam.md): no advice needed
    assert "one cell thick along z" in text
    assert yaml.safe_load(text)["box"]["sections"] == "xy"


@pytest.mark.parametrize("planform", [dict(sections="xz", semi_span=1.2, root_chord=1.0, taper=0.5,
                                           le_sweep_deg=40.0),        # low aspect ratio, swept (a fin)
                                      dict(sections="yx", semi_span=4.0, root_chord=1.0)])
def test_init_writes_the_axes_ffd_box_detects(tmp_path, planform):
    from ffdcli.app.prepare import prepare_box

    mesh = surface_mesh(Planform(**planform), n_chord=25, n_span=9)
    path = tmp_path / "w.su2"
    write_mesh(mesh, path)
    data = yaml.safe_load(starter_design(path, design_path=tmp_path / "w.yaml"))
    axes = prepare_box(path, use_cache=False).box.axes
    assert data["box"]["sections"] == axes.sections and data["box"]["root"] == axes.root


def test_init_then_deform_unedited_multizone_cgns_surface_is_byte_identical(tmp_path):
    import shutil

    from conftest import shared_file

    src = tmp_path / "w.cgns"
    shutil.copy(shared_file("cgns/aero__meshing__volume__wing.cgns"), src)
    out = _init_deform_roundtrip(tmp_path, src)
    assert out.read_bytes() == src.read_bytes()
