"""Inputs are checked as they are read: a damaged mesh (SU2, CGNS, VTK), a file that is not a
regular file, NaN coordinates, a bad airfoil target or lattice file, a foreign, corrupt or edited box
cache (rebuilt, never used) fail with one line naming the file (exit 2); the workspace is untouched.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REPO, SAMPLES, assert_clean_failure, file_hash, run_ffd
from hostile import (
    GOOD,
    _find,
    assert_hostile,
    bad_mesh,
    edit_design,
    ffd,
    mesh_lines,
    snapshot,
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


def test_box_lattice_file_missing(ws):
    """Found here: ``ffd box --from MISSING`` crashed with FileNotFoundError (exit 1)."""
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "wing", "--from", "nofile.xyz"], 2,
                   names=["nofile.xyz"])


def test_box_lattice_file_garbage(ws):
    (ws / "bad_lattice.xyz").write_text("1\n2 2 2\n0 0 0\n")
    assert_hostile(ws, ["box", "vwing.su2", "--surface", "wing", "--from", "bad_lattice.xyz"], 2,
                   names=["bad_lattice.xyz"])


def test_fit_target_garbage(ws):
    (ws / "junk.dat").write_text("this is not\nan airfoil\n")
    name = _airfoil_design(ws, "airfoil_fit.yaml", {"shape": {"upper": [0] * 6, "lower": [0] * 6}})
    assert_hostile(ws, ["fit", name, "--target", "junk.dat"], 2, names=["junk.dat"])


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


def test_zz_cache_not_poisoned(ws):
    assert file_hash(ws / "vwing.su2") == (ws / "vwing.su2.sha256").read_text()
    assert not list(ws.rglob("*.part*"))
    _good_run_reuses_or_rebuilds(ws, expect_from_cache=True)


@pytest.fixture(scope="module")
def nan_meshes(tmp_path_factory):
    from ffdcli.io.formats import write_mesh
    from ffdcli.testing.wings import Planform, extruded_wing_mesh

    d = tmp_path_factory.mktemp("nan")
    mesh = extruded_wing_mesh(Planform(), n_around=21, n_radial=5, n_span=4)
    out = {}
    for ext in ("vtu", "vtk", "cgns"):
        p = d / f"nan.{ext}"
        write_mesh(mesh, p)                    # our writers refuse NaN: damage the files afterwards
        out[ext] = p
    import h5py
    import meshio

    for ext in ("vtu", "vtk"):
        m = meshio.read(out[ext])
        m.points[17, 1] = np.nan
        m.points[40, 2] = np.inf
        meshio.write(out[ext], m, binary=False) if ext == "vtk" else meshio.write(out[ext], m)
    with h5py.File(out["cgns"], "r+") as h5:
        found = []
        h5.visititems(lambda name, obj: found.append(name) if name.endswith("CoordinateY/ data") else None)
        h5[found[0]][17] = np.nan
    return d, out
    return d, out


@pytest.mark.parametrize("ext", ["vtu", "vtk", "cgns"])
@pytest.mark.parametrize("command", ["inspect", "box"])
def test_nan_coordinates_in_every_format(nan_meshes, ext, command):
    """Found: accepted ('x nan .. nan'); box wrote a lattice and a cache; deform blamed the design."""
    d, meshes = nan_meshes
    args = [command, meshes[ext].name] + (["--surface", "wing"] if command == "box" else [])
    line = assert_hostile(d, args, 2, "NaN or infinite", "node 17", names=[f"nan.{ext}"])
    assert ext == "cgns" or "1 more" in line


@pytest.fixture()
def odd_inputs(ws2):
    made = []
    fifo = ws2 / "fifo_in.su2"
    os.mkfifo(fifo)
    made.append(fifo)
    for name, target in (("zero.su2", "/dev/zero"), ("loop_in.su2", "loop_in.su2"), ("zero_sens.csv", "/dev/zero")):
        (ws2 / name).symlink_to(target)
        made.append(ws2 / name)
    fifo_csv = ws2 / "fifo_sens.csv"
    os.mkfifo(fifo_csv)
    made.append(fifo_csv)
    yield ws2
    for p in made:
        p.unlink()


@pytest.mark.parametrize("args,what", [
    (["inspect", "fifo_in.su2"], "FIFO"), (["box", "fifo_in.su2", "--surface", "wing"], "FIFO"),
    (["check", "fifo_in.su2"], "FIFO"), (["inspect", "zero.su2"], "character device"),
    (["inspect", "loop_in.su2"], "symlink loop"),
    (["grad", "good.yaml", "--sens", "fifo_sens.csv"], "FIFO"),
    (["grad", "good.yaml", "--sens", "zero_sens.csv"], "character device"),
], ids=["inspect-fifo", "box-fifo", "check-fifo", "inspect-zero", "inspect-loop", "grad-fifo", "grad-zero"])
def test_non_regular_input(odd_inputs, args, what):
    """Found: a FIFO as MESH or --sens hung forever in open(). Run in a subprocess with a timeout."""
    before = snapshot(odd_inputs)
    proc = run_ffd(*args, cwd=odd_inputs, timeout=120)
    assert_clean_failure(proc, 2, what, args[-1] if args[0] != "box" else args[1])
    assert snapshot(odd_inputs) == before


@pytest.mark.parametrize("block", ["NELEM", "MARKER_ELEMS= 200"])
def test_huge_element_id_quoted_as_written(ws2, block):
    """Found: a 23-digit point id was quoted as 9223372036854775807 (int64's largest value)."""
    lines = (ws2 / "vwing.su2").read_text().splitlines(keepends=True)
    i = next(k for k, ln in enumerate(lines) if ln.startswith(block)) + 3
    parts = lines[i].split()
    parts[2] = "12345678901234567890123"
    lines[i] = "\t".join(parts) + "\n"
    (ws2 / "hugeid.su2").write_text("".join(lines))
    line = assert_hostile(ws2, ["inspect", "hugeid.su2"], 2, "12345678901234567890123", "out of range",
                          names=["hugeid.su2:"])
    assert "9223372036854775807" not in line


@pytest.fixture(scope="module")
def cached(tmp_path_factory):
    d = tmp_path_factory.mktemp("cache2")
    mesh = write_volume_wing(d)
    write_design(d, mesh, GOOD, name="good.yaml")
    proc = ffd("deform", "good.yaml", "-o", "ref.su2", "-q", cwd=d)
    assert proc.returncode == 0, proc.stderr
    caches = sorted(d.glob("vwing.su2.*.ffdcache.npz"))
    assert len(caches) == 1
    return d, caches[0]


def _run_from_cache(d: Path) -> bool:
    proc = ffd("deform", "good.yaml", "-o", "again.su2", "--json", cwd=d)
    assert proc.returncode == 0, proc.stderr
    assert file_hash(d / "again.su2") == file_hash(d / "ref.su2")
    return json.loads(proc.stdout)["from_cache"]


def _shift(v):
    w = v.copy()
    w[..., 1] += 1e-3
    return w


@pytest.mark.parametrize("array,damage", [
    ("inside", lambda v: np.zeros_like(v)),                 # found: an unmoved wing, exit 0
    ("control_points", _shift),                             # found: a different mesh, silently
    ("params", lambda v: np.clip(v + 0.01, 0, 1)),
    ("residual", lambda v: v + 0.5),
    ("header", lambda v: np.frombuffer(b"[1, 2, 3]", dtype=np.uint8)),   # found: AttributeError, every run
    ("header", lambda v: np.frombuffer(b'"just a string"', dtype=np.uint8)),
    ("header", lambda v: np.frombuffer(b"\xff\xfe", dtype=np.uint8)),
], ids=["inside_cleared", "control_points_shifted", "params_moved", "residual_edited", "header_list",
        "header_string", "header_not_utf8"])
def test_cache_edited_under_a_valid_header(cached, array, damage):
    d, cache = cached
    saved = cache.read_bytes()
    try:
        with np.load(cache, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        arrays[array] = damage(arrays[array])
        with open(cache, "wb") as fh:
            np.savez(fh, **arrays)
        assert _run_from_cache(d) is False          # rebuilt, the same mesh as the reference
        assert _run_from_cache(d) is True           # and the rebuilt cache is used
    finally:
        cache.write_bytes(saved)


def test_fifo_named_in_the_design_file(ws2):
    """Found: a FIFO, /dev/zero or a symlink loop given in a design file was 'not found'."""
    import yaml

    fifo = ws2 / "fifo_mesh.su2"
    os.mkfifo(fifo)
    (ws2 / "zero_mesh.su2").symlink_to("/dev/zero")
    try:
        for target, what, named in (("fifo_mesh.su2", "FIFO", "fifo_mesh.su2"),
                                    ("zero_mesh.su2", "character device", "/dev/zero")):
            data = yaml.safe_load((ws2 / "good.yaml").read_text())
            data["mesh"] = target
            (ws2 / "odd_mesh.yaml").write_text(yaml.safe_dump(data))
            line = assert_hostile(ws2, ["deform", "odd_mesh.yaml"], 2, what, named, names=["odd_mesh.yaml:", "mesh"])
            assert "not found" not in line
        assert_hostile(ws2, ["deform", "fifo_mesh.su2"], 2, "FIFO")
    finally:
        fifo.unlink()
        (ws2 / "zero_mesh.su2").unlink()

