"""OpenFOAM polyMeshes without OpenFOAM: generated cases in every file form, read back, written as a
copy of the case with new points, the geometry and the gate on polyhedral cells, bad input."""

from __future__ import annotations

import gzip
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import run_ffd

from ffdcli.errors import InputError
from ffdcli.io.formats import openfoam, read_mesh, write_mesh
from ffdcli.io.formats.foamfile import parse_ints
from ffdcli.io.formats.openfoam_case import polymesh_of, write_case
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.mesh.polyhedra import (
    cell_centres_volumes,
    counted_offsets,
    counted_offsets_reference,
    face_centres_areas,
    from_counted,
    polyhedra_from_cells,
    reverse_faces,
    split_counted,
)
from ffdcli.quality.polyhedral import check_quality_poly, poly_figures
from ffdcli.testing.wings import extruded_wing_mesh, hex_volumes

FORMS = [dict(binary=b, compress=c, label=lab, scalar=sc)
         for b in (False, True) for c in (False, True) for lab, sc in ((32, 64), (64, 64), (32, 32))
         if not (not b and sc == 32)]


@pytest.fixture(scope="module")
def wing():
    """A small hexahedral wing mesh (no gmsh) and its polyMesh."""
    mesh = extruded_wing_mesh(n_around=25, n_radial=7, n_span=4)
    poly, patches = polymesh_of(mesh, wall=("wing",))
    return mesh, poly, patches


def _case(tmp_path, wing, name="case", **form):
    mesh, poly, patches = wing
    return write_case(tmp_path / name, mesh.points, poly, patches, **form)


@pytest.mark.parametrize("form", FORMS, ids=lambda f: "-".join(f"{k}{v}" for k, v in f.items()))
def test_every_file_form_reads_the_same_mesh(tmp_path, wing, form):
    mesh, poly, patches = wing
    case = _case(tmp_path, wing, **form)
    got = read_mesh(case)
    tol = 0 if form["scalar"] == 64 else 1e-6
    assert np.allclose(got.points, mesh.points, rtol=0, atol=tol)
    if tol == 0:
        assert np.array_equal(got.points, mesh.points)
    p = got.polyhedra
    assert np.array_equal(p.face_nodes, poly.face_nodes) and np.array_equal(p.face_offsets, poly.face_offsets)
    assert np.array_equal(p.owner, poly.owner) and np.array_equal(p.neighbour, poly.neighbour)
    assert list(got.markers) == list(mesh.markers)
    assert [(x.name, x.type) for x in got.source.patches] == [(x.name, x.type) for x in patches]
    for name in mesh.markers:
        assert np.array_equal(got.marker_point_ids(name), mesh.marker_point_ids(name))
    assert got.n_cells == len(mesh.cells[0]) and got.format == "openfoam"
    # the polyMesh folder itself is a mesh too
    assert read_mesh(case / "constant" / "polyMesh").n_cells == got.n_cells


def test_counted_records_match_the_reference():
    rng = np.random.default_rng(3)
    sizes = rng.integers(3, 9, 500)
    tokens = np.concatenate([np.concatenate([[k], rng.integers(0, 99, k)]) for k in sizes])
    assert np.array_equal(counted_offsets(tokens, len(sizes)), counted_offsets_reference(tokens, len(sizes)))
    for bad in (tokens[:-1], np.append(tokens, 1)):
        with pytest.raises(ValueError):
            counted_offsets(bad, len(sizes))
        with pytest.raises(ValueError):
            counted_offsets_reference(bad, len(sizes))


def test_compiled_parsers_match_their_references():
    rng = np.random.default_rng(5)
    sizes = rng.integers(3, 8, 300)
    faces = [rng.integers(0, 10**6, k) for k in sizes]
    text = "".join(f"{len(f)}(" + " ".join(map(str, f)) + ")\n" for f in faces).encode()
    got, ok = parse_ints(np.frombuffer(text, dtype=np.uint8))
    ref = np.fromstring(text.translate(bytes.maketrans(b"()", b"  ")).decode(), dtype=np.int64, sep=" ")
    assert ok and np.array_equal(got, ref)
    nodes, offsets = split_counted(got, len(sizes))
    n2, o2 = from_counted(got, counted_offsets_reference(got, len(sizes)))
    assert np.array_equal(nodes, n2) and np.array_equal(offsets, o2)
    assert not parse_ints(np.frombuffer(b"1 2 x 3", dtype=np.uint8))[1]


def test_face_geometry_kernel_matches_the_numpy_reference(wing):
    from ffdcli.mesh.polyhedra import Polyhedra

    rng = np.random.default_rng(11)
    sizes = rng.integers(3, 9, 400)                    # triangles to octagons, warped
    pts, nodes = [], []
    for k in sizes:
        t = np.sort(rng.uniform(0, 2 * np.pi, k))
        ring = np.column_stack([np.cos(t), np.sin(t), 0.05 * rng.normal(size=k)]) + rng.normal(size=3)
        first = sum(len(p) for p in pts)
        nodes.append(np.arange(first, first + k))
        pts.append(ring)
    pts = np.vstack(pts)
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    poly = Polyhedra(np.concatenate(nodes), offsets, np.zeros(len(sizes), np.int64),
                     np.full(len(sizes), -1, np.int64), 1)
    for got, ref in zip(face_centres_areas(pts, poly), face_centres_areas(pts, poly, compiled=False), strict=True):
        assert np.allclose(got, ref, rtol=1e-13, atol=1e-14)
    mesh, wpoly, _ = wing
    for got, ref in zip(face_centres_areas(mesh.points, wpoly), face_centres_areas(mesh.points, wpoly, compiled=False),
                        strict=True):
        assert np.allclose(got, ref, rtol=1e-13, atol=1e-15)


def test_volumes_are_the_cells_volumes(wing):
    mesh, poly, _ = wing
    fc, fa = face_centres_areas(mesh.points, poly)
    _, vol = cell_centres_volumes(poly, fc, fa)
    # hex_volumes gives the smallest corner tetrahedron; on these near-box cells the exact volume is
    # the sum of the pyramids, compared with a triple-product decomposition of each hexahedron
    hexes = mesh.cells[0].data
    p = mesh.points[hexes]
    split = [(0, 1, 3, 4), (1, 2, 3, 6), (1, 4, 5, 6), (3, 4, 6, 7), (1, 3, 4, 6)]
    exact = sum(np.einsum("ij,ij->i", np.cross(p[:, b] - p[:, a], p[:, c] - p[:, a]), p[:, d] - p[:, a]) / 6
                for a, b, c, d in split)
    assert np.allclose(vol, exact, rtol=1e-6)
    assert (hex_volumes(mesh.points, hexes) > 0).all()


def test_box_grid_is_orthogonal_and_unskewed():
    n = 4
    x = np.linspace(0, 1, n + 1)
    pts = np.stack(np.meshgrid(x, 2 * x, 3 * x, indexing="ij"), -1).reshape(-1, 3)
    idx = np.arange(len(pts)).reshape(n + 1, n + 1, n + 1)
    c = [idx[i:n + i, j:n + j, k:n + k].ravel() for i, j, k in
         [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]]
    poly, _ = polyhedra_from_cells([CellBlock("hexahedron", np.column_stack(c))])
    fig = poly_figures(pts, poly)
    assert np.allclose(fig.volumes, 6.0 / n**3) and np.allclose(fig.non_orth, 0, atol=1e-6)
    assert fig.skew.max() < 1e-9 and np.allclose(fig.q, 1.0)
    # a reversed face is a face-pyramid error of its owner: the gate's value goes <= 0 there
    bad = reverse_faces(poly.face_nodes, poly.face_offsets, np.arange(poly.n_faces) == 0)
    broken = type(poly)(bad, poly.face_offsets, poly.owner, poly.neighbour, poly.n_cells)
    fig2 = poly_figures(pts, broken)
    assert fig2.pyramid_errors[0] and fig2.q[poly.owner[0]] <= 0


def test_zero_design_copies_the_case_byte_for_byte(tmp_path, wing):
    case = _case(tmp_path, wing, binary=True, compress=True)
    (case / "0").mkdir()
    (case / "0" / "U").write_text("a field\n")
    (case / "5").mkdir()                      # a result of the old mesh: not copied
    mesh = read_mesh(case)
    out = tmp_path / "out_case"
    write_mesh(mesh, out)
    for f in case.rglob("*"):
        rel = f.relative_to(case)
        if f.is_file() and rel.parts[0] != "5":
            assert (out / rel).read_bytes() == f.read_bytes(), rel
    assert not (out / "5").exists()


@pytest.mark.parametrize("form", [FORMS[0], FORMS[3], FORMS[-1]], ids=["ascii", "ascii-gz", "binary-gz-s32"])
def test_moved_points_keep_the_file_form(tmp_path, wing, form):
    case = _case(tmp_path, wing, **form)
    before = {f: f.read_bytes() for f in case.rglob("*") if f.is_file()}
    mesh = read_mesh(case)
    moved = mesh.points + 1e-3 * np.sin(mesh.points[:, [1, 2, 0]] * 3.0)
    out = tmp_path / "moved"
    write_mesh(mesh, out, moved)
    assert {f: f.read_bytes() for f in case.rglob("*") if f.is_file()} == before      # input untouched
    got = read_mesh(out)
    if form["scalar"] == 64:
        assert np.array_equal(got.points, moved)
    else:
        assert np.allclose(got.points, moved, atol=1e-6)
    pm = out / "constant" / "polyMesh"
    name = "points.gz" if form["compress"] else "points"
    assert sorted(p.name for p in pm.iterdir()) == sorted(p.name for p in (case / "constant" / "polyMesh").iterdir())
    new = pm / name
    raw = gzip.decompress(new.read_bytes()) if form["compress"] else new.read_bytes()
    old = (case / "constant" / "polyMesh" / name).read_bytes()
    old = gzip.decompress(old) if form["compress"] else old
    head = old[:old.index(b"FoamFile")]
    assert raw.startswith(head) and raw[:raw.index(b"}")] == old[:old.index(b"}")]     # same header
    for f in ("faces", "owner", "neighbour", "boundary"):
        a = next(pm.glob(f + "*"))
        assert a.read_bytes() == (case / "constant" / "polyMesh" / a.name).read_bytes()


def _corrupt(case: Path, name: str, edit) -> None:
    p = case / "constant" / "polyMesh" / name
    p.write_bytes(edit(p.read_bytes()))


BAD = {
    "missing faces": ("faces", None, "missing polyMesh file 'faces'"),
    "truncated points": ("points", lambda b: b[: len(b) // 2], "points"),
    "point out of range": ("faces", lambda b: b.replace(b"4(0 ", b"4(999999 ", 1), "refers to point 999999"),
    "owner count": ("owner", lambda b: b.replace(b"\n(\n", b"\n(\n0\n", 1).replace(
        b"nFaces", b"nFaces", 1), "owner"),
    "note lies": ("owner", lambda b: b.replace(b"nCells:", b"nCells:1", 1), "the header's note says nCells"),
    "a word in faces": ("faces", lambda b: b.replace(b"4(0 ", b"4(x ", 1), "'x' is not an integer"),
}


@pytest.mark.parametrize("what", list(BAD))
def test_bad_ascii_input_names_file_and_line(tmp_path, wing, what):
    case = _case(tmp_path, wing)
    name, edit, words = BAD[what]
    if edit is None:
        (case / "constant" / "polyMesh" / name).unlink()
    elif what == "owner count":
        p = case / "constant" / "polyMesh" / "owner"
        text = p.read_bytes()
        n = int(text.split(b"\n(\n")[0].split()[-1])
        p.write_bytes(text.replace(f"\n{n}\n(\n".encode(), f"\n{n + 1}\n(\n0\n".encode(), 1))
        words = f"owner has {n + 1} entries"
    else:
        _corrupt(case, name, edit)
    with pytest.raises(InputError) as e:
        read_mesh(case)
    assert words in str(e.value) and name in str(e.value)
    if what in ("point out of range", "a word in faces"):
        assert e.value.line is not None or "entry" in str(e.value)


def test_binary_header_lying_about_label_size(tmp_path, wing):
    case = _case(tmp_path, wing, binary=True)
    _corrupt(case, "owner", lambda b: b.replace(b"label=32", b"label=64", 1))
    with pytest.raises(InputError, match="owner.*arch"):
        read_mesh(case)
    case2 = _case(tmp_path, wing, name="c2", binary=True)
    _corrupt(case2, "points", lambda b: b[:-40])
    with pytest.raises(InputError, match="truncated"):
        read_mesh(case2)


def test_gate_refuses_an_inverting_move(wing):
    mesh, poly, _ = wing
    m = Mesh(points=mesh.points, dim=3, markers=mesh.markers, polyhedra=poly, format="openfoam")
    ok = check_quality_poly(m, mesh.points * 1.01)
    assert ok.ok and ok.count == poly.n_cells and ok.polyhedral["before"] is not None
    bad = mesh.points.copy()
    wall = mesh.marker_point_ids("wing")
    bad[wall] += np.array([0.0, 0.3, 0.0])          # the wing pushed through its first cells
    rep = check_quality_poly(m, bad)
    assert not rep.ok and rep.n_new_inverted > 0
    assert rep.polyhedral["after"]["face_pyramid_errors"] > 0 and "face pyramid" in rep.summary()


def test_face_rule_is_relative_to_the_baseline_and_its_worst():
    from ffdcli.quality.polyhedral import PolyFigures, face_rule

    def fig(non_orth, skew):
        n = len(skew)
        return PolyFigures(volumes=np.ones(1), centres=np.zeros((1, 3)), q=np.ones(1), non_orth=np.array(non_orth),
                           skew=np.array(skew), pyramid_errors=np.zeros(n, bool), internal=np.ones(n, bool))

    ref = fig([10.0, 60.0, 75.0], [1.0, 3.0, 9.0])
    # skewness 3 -> 8: above 4 and doubled, but below the input's worst (9): accepted
    assert not face_rule(fig([10.0, 60.0, 75.0], [1.0, 8.0, 9.0]), ref, 20.0, 10.0, 0.5).any()
    # 3 -> 9.5: beyond the input's worst, tripled: refused
    assert face_rule(fig([10.0, 60.0, 75.0], [1.0, 9.5, 9.0]), ref, 20.0, 10.0, 0.5).tolist() == [False, True, False]
    # non-orthogonality 60 -> 76 (grew 16 deg, beyond 70 and the worst 75): refused; 60 -> 74: not
    assert face_rule(fig([10.0, 76.0, 75.0], [1.0, 3.0, 9.0]), ref, 20.0, 10.0, 0.5)[1]
    assert not face_rule(fig([10.0, 74.0, 75.0], [1.0, 3.0, 9.0]), ref, 20.0, 10.0, 0.5).any()
    assert not face_rule(ref, None, 20.0, 10.0, 0.5).any()


def test_cli_deform_check_inspect_on_a_case(tmp_path, wing):
    case = _case(tmp_path, wing, binary=True, compress=True)
    design = tmp_path / "twist.yaml"
    design.write_text(f"mesh: {case.name}\nsurface: wing\nbox: {{points: [5, 4, 2]}}\n"
                      "changes:\n  - twist: {tip: 3}\n")
    r = run_ffd("deform", design, "--json", cwd=tmp_path)      # default output: out/twist, a case folder
    assert r.returncode == 0, r.stderr
    out = tmp_path / "out" / "twist"
    assert (out / "constant" / "polyMesh" / "points.gz").is_file() and (out / "system" / "controlDict").is_file()
    assert not list((tmp_path / "out").glob(".*part*"))
    got, src = read_mesh(out), read_mesh(case)
    wall = src.marker_point_ids("wing")
    assert np.abs(got.points[wall] - src.points[wall]).max() > 1e-3          # the wing moved
    inner = np.setdiff1d(np.arange(src.n_points), np.concatenate([src.marker_point_ids(n) for n in src.markers]))
    assert np.abs(got.points[inner] - src.points[inner]).max() > 0           # and the volume
    r = run_ffd("check", out, cwd=tmp_path)
    assert r.returncode == 0 and "checkMesh's figures" in r.stdout
    r = run_ffd("inspect", case, cwd=tmp_path)
    assert r.returncode == 0 and "OPENFOAM" in r.stdout and "hexahedra" in r.stdout
    # a second run replaces the case whole; a folder that is not a case is never replaced
    (out / "marker").write_text("old")
    assert run_ffd("deform", design, cwd=tmp_path).returncode == 0
    assert not (out / "marker").exists()
    shutil.rmtree(out)
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    r = run_ffd("deform", design, cwd=tmp_path)
    assert r.returncode == 2 and "not an OpenFOAM case" in r.stderr and (out / "notes.txt").read_text() == "mine"
    # an output with a file extension from a case input: refused before any work
    r = run_ffd("deform", design, "-o", tmp_path / "out.su2", cwd=tmp_path)
    assert r.returncode == 2 and "OpenFOAM case" in r.stderr and not (tmp_path / "out.su2").exists()


def test_cli_bad_case_exit_2_nothing_written(tmp_path, wing):
    case = _case(tmp_path, wing)
    _corrupt(case, "faces", lambda b: b.replace(b"4(0 ", b"4(999999 ", 1))
    design = tmp_path / "d.yaml"
    design.write_text(f"mesh: {case.name}\nsurface: wing\nchanges:\n  - twist: {{tip: 3}}\n")
    r = run_ffd("deform", design, cwd=tmp_path)
    assert r.returncode == 2 and "faces" in r.stderr and "999999" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "out" / "d").exists()
    r = run_ffd("check", tmp_path / "nowhere", cwd=tmp_path)
    assert r.returncode == 2 and "no such mesh file or OpenFOAM case folder" in r.stderr
    (tmp_path / "empty").mkdir()
    r = run_ffd("inspect", tmp_path / "empty", cwd=tmp_path)
    assert r.returncode == 2 and "without an OpenFOAM mesh" in r.stderr


def test_output_inside_the_case_is_not_copied_into_itself(tmp_path, wing):
    case = _case(tmp_path, wing)
    (case / "out").mkdir()
    mesh = read_mesh(case)
    write_mesh(mesh, case / "out" / "copy")
    write_mesh(mesh, case / "out" / "copy2")
    assert not (case / "out" / "copy2" / "out").exists()
    assert openfoam.poly_mesh_folder(case / "out" / "copy2")


def test_2d_case_with_one_empty_patch_deforms_in_plane(tmp_path):
    """A one-cell-thick case whose front and back planes are one patch (OpenFOAM's ``empty``, as
    airFoil2D's frontAndBack): each node slides in its own plane, so a twist of both sections works
    and every node keeps its z."""
    from ffdcli.testing.wings import Planform

    m = extruded_wing_mesh(Planform(semi_span=0.1, root_chord=1.0, sections="xy"), n_around=33, n_radial=9,
                           n_span=2)
    m.markers["frontAndBack"] = m.markers.pop("symmetry") + m.markers.pop("side")
    poly, patches = polymesh_of(m, wall=("wing",))
    case = write_case(tmp_path / "af", m.points, poly, patches)
    design = tmp_path / "d.yaml"
    design.write_text("mesh: af\nbox: {points: [6, 2, 2], sections: xy}\nchanges:\n  - twist: [2, 2]\n")
    r = run_ffd("deform", design, cwd=tmp_path)          # the surface: the only wall patch
    assert r.returncode == 0, r.stderr
    got, src = read_mesh(tmp_path / "out" / "d"), read_mesh(case)
    assert np.array_equal(got.points[:, 2], src.points[:, 2])
    assert np.abs(got.points - src.points).max() > 1e-3


def test_folder_output_is_whole_or_nothing_and_stale_folders_are_swept(tmp_path, wing):
    from ffdcli.io.atomic import _HOST
    from ffdcli.io.outputs import plan_outputs

    case = _case(tmp_path, wing)
    mesh = read_mesh(case)
    out = tmp_path / "result"
    stale = tmp_path / f".result.{_HOST}-999999-abc123.part"           # a killed run's folder
    stale.mkdir()
    (stale / "constant").mkdir()
    plan = plan_outputs([("mesh", out)], inputs=(case,))

    def broken(tmp):
        write_mesh(mesh, tmp, mesh.points + 1.0)
        raise OSError(28, "No space left on device")

    with pytest.raises(Exception, match="no space left"):
        plan.write({"mesh": broken})
    assert not out.exists() and not stale.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    assert plan.write({"mesh": lambda tmp: write_mesh(mesh, tmp, mesh.points + 1.0)}) == {"mesh": str(out)}
    assert np.array_equal(read_mesh(out).points, mesh.points + 1.0)


def test_init_and_box_take_a_case(tmp_path, wing):
    case = _case(tmp_path, wing, binary=True)
    r = run_ffd("init", case, "-o", tmp_path / "start.yaml", cwd=tmp_path)     # the wall patch is the surface
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "start.yaml").read_text()
    assert "mesh: case" in text and "surface: wing" in text
    r = run_ffd("deform", tmp_path / "start.yaml", cwd=tmp_path)             # unedited: the input back
    assert r.returncode == 0, r.stderr
    out = tmp_path / "out" / "start"
    for f in (case / "constant" / "polyMesh").iterdir():
        assert (out / "constant" / "polyMesh" / f.name).read_bytes() == f.read_bytes()
    r = run_ffd("box", case, "--surface", "wing", "--points", "5,4,2", "--lattice", tmp_path / "l.vtk", cwd=tmp_path)
    assert r.returncode == 0 and (tmp_path / "l.vtk").is_file(), r.stderr
